//! Replay of a folder of still images (PNG or JPEG), in file-name order, at a fixed frame rate.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use super::{read_image_file, CaptureError, Frame, FrameSource, SourceInfo};

pub struct ImageFolder {
    folder: PathBuf,
    files: Vec<PathBuf>,
    next: usize,
    period: Duration,
    looping: bool,
    next_due: Option<Instant>,
    size: (u32, u32),
}

impl ImageFolder {
    /// Lists the folder's images; `looping` starts over after the last one instead of ending.
    pub fn open(folder: &Path, fps: f64, looping: bool) -> Result<Self, CaptureError> {
        let path_text = folder.display().to_string();
        let entries = std::fs::read_dir(folder).map_err(|source| CaptureError::Io {
            path: path_text.clone(),
            source,
        })?;
        let mut files: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                let ext = p
                    .extension()
                    .and_then(|e| e.to_str())
                    .unwrap_or("")
                    .to_ascii_lowercase();
                matches!(ext.as_str(), "png" | "jpg" | "jpeg")
            })
            .collect();
        files.sort();
        let first = files.first().ok_or_else(|| CaptureError::Empty(path_text.clone()))?;
        let size = image::image_dimensions(first).map_err(|e| CaptureError::Image {
            origin: first.display().to_string(),
            message: e.to_string(),
        })?;
        let fps = if fps.is_finite() && fps > 0.0 { fps } else { 30.0 };
        Ok(Self {
            folder: folder.to_path_buf(),
            files,
            next: 0,
            period: Duration::from_secs_f64(1.0 / fps),
            looping,
            next_due: None,
            size,
        })
    }

    /// Hands out frames as fast as they are asked for (batch processing rather than live replay).
    pub fn unpaced(mut self) -> Self {
        self.period = Duration::ZERO;
        self
    }

    pub fn len(&self) -> usize {
        self.files.len()
    }

    pub fn is_empty(&self) -> bool {
        self.files.is_empty()
    }
}

impl FrameSource for ImageFolder {
    fn info(&self) -> SourceInfo {
        SourceInfo {
            kind: "replay",
            name: self.folder.display().to_string(),
            width: self.size.0,
            height: self.size.1,
            fps: if self.period.is_zero() {
                0.0
            } else {
                1.0 / self.period.as_secs_f64()
            },
        }
    }

    fn next_frame(&mut self) -> Result<Frame, CaptureError> {
        if self.next >= self.files.len() {
            if !self.looping {
                return Err(CaptureError::EndOfStream);
            }
            self.next = 0;
        }
        let path = &self.files[self.next];
        self.next += 1;
        if let Some(due) = self.next_due {
            let now = Instant::now();
            if due > now {
                std::thread::sleep(due - now);
            }
        }
        self.next_due = Some(Instant::now() + self.period);
        read_image_file(path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plays_images_in_name_order_then_ends_or_loops() {
        let dir = tempfile::tempdir().unwrap();
        for (name, shade) in [("b.png", 20u8), ("a.png", 10), ("c.jpg", 200)] {
            image::RgbImage::from_pixel(8, 6, image::Rgb([shade; 3]))
                .save(dir.path().join(name))
                .unwrap();
        }
        std::fs::write(dir.path().join("notes.txt"), "not a frame").unwrap();
        let mut folder = ImageFolder::open(dir.path(), 30.0, false).unwrap().unpaced();
        assert_eq!(folder.len(), 3);
        assert_eq!((folder.info().width, folder.info().height), (8, 6));
        let shades: Vec<u8> = (0..3)
            .map(|_| folder.next_frame().unwrap().to_rgb().unwrap().get_pixel(0, 0)[0])
            .collect();
        assert_eq!(&shades[..2], &[10, 20]);
        assert!(shades[2] > 150, "JPEG frame decoded: {shades:?}");
        assert!(matches!(folder.next_frame(), Err(CaptureError::EndOfStream)));

        let mut looping = ImageFolder::open(dir.path(), 30.0, true).unwrap().unpaced();
        for _ in 0..4 {
            looping.next_frame().unwrap();
        }
    }

    #[test]
    fn an_empty_folder_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        assert!(matches!(
            ImageFolder::open(dir.path(), 30.0, false),
            Err(CaptureError::Empty(_))
        ));
    }
}

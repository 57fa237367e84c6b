//! Where the API may write: recordings go into one folder (by default `$XDG_DATA_HOME/nusense/recordings`, that
//! is `~/.local/share/nusense/recordings`), under names relative to it. An absolute name, a `..`, a name that
//! leads out of the folder through a symbolic link, or an existing file (unless overwriting is asked for) is
//! refused before anything is created.

use std::fs::OpenOptions;
use std::path::{Component, Path, PathBuf};

/// The recordings folder.
#[derive(Clone, Debug)]
pub struct RecordingsDir {
    root: PathBuf,
}

#[derive(Debug, thiserror::Error)]
pub enum RecordingPathError {
    #[error("recording names are relative to the recordings folder {root}; `{name}` is an absolute path")]
    Absolute { name: String, root: String },
    #[error("recording names stay inside the recordings folder {root}; `{name}` climbs out of it with `..`")]
    ParentDir { name: String, root: String },
    #[error("`{name}` leads out of the recordings folder {root} (through a symbolic link)")]
    Escapes { name: String, root: String },
    #[error("a recording's name must end in .mcap (got `{name}`)")]
    Extension { name: String },
    #[error("`{name}` is not a file name")]
    Empty { name: String },
    #[error("{path} already exists; choose another name, or pass \"overwrite\": true to replace it")]
    Exists { path: String },
    #[error("cannot create {path}")]
    Create {
        path: String,
        #[source]
        source: std::io::Error,
    },
}

impl RecordingsDir {
    pub fn new(root: PathBuf) -> Self {
        Self { root }
    }

    /// `$XDG_DATA_HOME/nusense/recordings` (`~/.local/share/nusense/recordings` when XDG_DATA_HOME is unset).
    pub fn default_location() -> Option<PathBuf> {
        dirs::data_dir().map(|data| data.join("nusense").join("recordings"))
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Checks `name` and creates the (empty) file it names, so that nothing else can be overwritten between the
    /// check and the recorder opening it. `overwrite` replaces an existing recording.
    pub fn create(&self, name: &Path, overwrite: bool) -> Result<PathBuf, RecordingPathError> {
        let text = name.display().to_string();
        let root_text = self.root.display().to_string();
        if name.is_absolute() || name.has_root() {
            return Err(RecordingPathError::Absolute {
                name: text,
                root: root_text,
            });
        }
        let mut normal = 0;
        for component in name.components() {
            match component {
                Component::Normal(_) => normal += 1,
                Component::CurDir => {}
                Component::ParentDir => {
                    return Err(RecordingPathError::ParentDir {
                        name: text,
                        root: root_text,
                    })
                }
                Component::RootDir | Component::Prefix(_) => {
                    return Err(RecordingPathError::Absolute {
                        name: text,
                        root: root_text,
                    })
                }
            }
        }
        if normal == 0 {
            return Err(RecordingPathError::Empty { name: text });
        }
        if name.extension().and_then(|e| e.to_str()) != Some("mcap") {
            return Err(RecordingPathError::Extension { name: text });
        }
        let path = self.root.join(name);
        let create_error = |path: &Path, source| RecordingPathError::Create {
            path: path.display().to_string(),
            source,
        };
        let parent = path.parent().unwrap_or(&self.root);
        std::fs::create_dir_all(parent).map_err(|e| create_error(parent, e))?;
        let root = self.root.canonicalize().map_err(|e| create_error(&self.root, e))?;
        let real_parent = parent.canonicalize().map_err(|e| create_error(parent, e))?;
        if !real_parent.starts_with(&root) {
            return Err(RecordingPathError::Escapes {
                name: text,
                root: root_text,
            });
        }
        if path.is_symlink() {
            // Even with overwrite: replacing a link's target would write wherever it points.
            return Err(RecordingPathError::Escapes {
                name: text,
                root: root_text,
            });
        }
        let mut options = OpenOptions::new();
        options.write(true);
        if overwrite {
            options.create(true).truncate(true);
        } else {
            options.create_new(true);
        }
        match options.open(&path) {
            Ok(_) => Ok(path),
            Err(error) if error.kind() == std::io::ErrorKind::AlreadyExists => Err(RecordingPathError::Exists {
                path: path.display().to_string(),
            }),
            Err(error) => Err(create_error(&path, error)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_stay_inside_the_folder() {
        let dir = tempfile::tempdir().unwrap();
        let recordings = RecordingsDir::new(dir.path().join("recordings"));
        for (name, expect) in [
            ("/tmp/x.mcap", "absolute"),
            ("../x.mcap", "climbs out"),
            ("a/../../x.mcap", "climbs out"),
            ("run.txt", ".mcap"),
            (".", "not a file name"),
        ] {
            let error = recordings.create(Path::new(name), false).unwrap_err().to_string();
            assert!(error.contains(expect), "{name}: {error}");
        }
        let path = recordings.create(Path::new("day1/./run.mcap"), false).unwrap();
        assert!(
            path.starts_with(dir.path().join("recordings/day1")),
            "{}",
            path.display()
        );
        assert!(path.is_file());
    }

    #[test]
    fn existing_recordings_are_kept_unless_overwriting_is_asked_for() {
        let dir = tempfile::tempdir().unwrap();
        let recordings = RecordingsDir::new(dir.path().to_path_buf());
        std::fs::write(dir.path().join("kept.mcap"), b"precious").unwrap();
        let error = recordings.create(Path::new("kept.mcap"), false).unwrap_err();
        assert!(matches!(error, RecordingPathError::Exists { .. }), "{error}");
        assert_eq!(std::fs::read(dir.path().join("kept.mcap")).unwrap(), b"precious");
        recordings.create(Path::new("kept.mcap"), true).unwrap();
        assert_eq!(std::fs::read(dir.path().join("kept.mcap")).unwrap(), b"");
    }

    #[test]
    fn symbolic_links_out_of_the_folder_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let outside = tempfile::tempdir().unwrap();
        let root = dir.path().join("recordings");
        std::fs::create_dir_all(&root).unwrap();
        std::os::unix::fs::symlink(outside.path(), root.join("out")).unwrap();
        std::os::unix::fs::symlink(outside.path().join("victim.mcap"), root.join("link.mcap")).unwrap();
        let recordings = RecordingsDir::new(root);
        for name in ["out/x.mcap", "link.mcap"] {
            let error = recordings.create(Path::new(name), true).unwrap_err();
            assert!(matches!(error, RecordingPathError::Escapes { .. }), "{name}: {error}");
        }
        assert_eq!(
            std::fs::read_dir(outside.path()).unwrap().count(),
            0,
            "nothing written outside"
        );
    }
}

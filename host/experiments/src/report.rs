//! What every report is: Markdown, SVG plots and JSON, written to a folder.

use std::path::{Path, PathBuf};

use nusense_daemon::record::RecordError;
use nusense_estimator::calibration::CalibrationError;
use thiserror::Error;

#[derive(Debug, Error)]
pub enum ReportError {
    #[error(transparent)]
    Recording(#[from] RecordError),
    #[error("{path}: reading message {sequence} is not a reading: {source}")]
    Reading {
        path: String,
        sequence: u32,
        source: serde_json::Error,
    },
    #[error(
        "{path} holds no reading with an estimate ({without_estimate} without): record with the estimator running"
    )]
    NoReadings { path: String, without_estimate: usize },
    #[error("cannot read {path}: {source}")]
    Read { path: String, source: std::io::Error },
    #[error("cannot write {path}: {source}")]
    Write { path: String, source: std::io::Error },
    #[error("{path}: {source}")]
    ForceLog { path: String, source: CalibrationError },
    #[error("{path}, line {line}: {message}")]
    Csv { path: String, line: usize, message: String },
    #[error("{0}")]
    Calibration(#[from] CalibrationError),
    #[error("{what}: {detail}")]
    NotEnoughData { what: &'static str, detail: String },
    #[error("drawing {name}: {message}")]
    Plot { name: String, message: String },
}

/// A finished report: its Markdown (which links the plots by file name), the plots and the JSON.
#[derive(Clone, Debug)]
pub struct Report {
    pub kind: &'static str,
    pub markdown: String,
    /// (file name, SVG document).
    pub plots: Vec<(String, String)>,
    pub json: serde_json::Value,
}

impl Report {
    /// Writes `report.md`, `report.json` and the plots into `dir` (created if missing); returns the files.
    pub fn write(&self, dir: &Path) -> Result<Vec<PathBuf>, ReportError> {
        let write = |name: &str, bytes: &[u8]| {
            let path = dir.join(name);
            std::fs::write(&path, bytes)
                .map(|_| path.clone())
                .map_err(|source| ReportError::Write {
                    path: path.display().to_string(),
                    source,
                })
        };
        std::fs::create_dir_all(dir).map_err(|source| ReportError::Write {
            path: dir.display().to_string(),
            source,
        })?;
        let mut files = vec![write("report.md", self.markdown.as_bytes())?];
        let json = serde_json::to_string_pretty(&self.json).expect("report JSON is plain data");
        files.push(write("report.json", json.as_bytes())?);
        for (name, svg) in &self.plots {
            files.push(write(name, svg.as_bytes())?);
        }
        Ok(files)
    }
}

/// Renders a chart into a report's plot list, naming the error after the file.
pub(crate) fn plot(name: &str, chart: &crate::plot::Chart) -> Result<(String, String), ReportError> {
    chart
        .to_svg()
        .map(|svg| (name.to_string(), svg))
        .map_err(|message| ReportError::Plot {
            name: name.to_string(),
            message,
        })
}

/// A Markdown table.
pub(crate) fn table(header: &[&str], rows: &[Vec<String>]) -> String {
    let mut out = format!("| {} |\n|{}\n", header.join(" | "), "---|".repeat(header.len()));
    for row in rows {
        out.push_str(&format!("| {} |\n", row.join(" | ")));
    }
    out
}

pub(crate) fn read_text(path: &Path) -> Result<String, ReportError> {
    std::fs::read_to_string(path).map_err(|source| ReportError::Read {
        path: path.display().to_string(),
        source,
    })
}

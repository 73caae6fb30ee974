//! A run folder's decision log written by hand, as `fly` writes it (the header line, then one
//! record a line), for the tests that make runs with chosen observations (calibrate, the fleet).

use companion::decision_log::Header;
use companion_core::record::DecisionRecord;
use std::io::Write;
use std::path::Path;

/// `DIR/decisions.jsonl`, its header written; add records with [`RunLog::record`].
pub struct RunLog(std::io::BufWriter<std::fs::File>);

impl RunLog {
    /// Creates `dir` (and its parents) and the log in it, and writes `header`.
    pub fn create(dir: &Path, header: &Header) -> Self {
        std::fs::create_dir_all(dir).unwrap();
        let f = std::fs::File::create(dir.join("decisions.jsonl")).unwrap();
        let mut log = Self(std::io::BufWriter::new(f));
        log.line(header);
        log
    }

    /// One record, one line.
    pub fn record(&mut self, r: &DecisionRecord) {
        self.line(r);
    }

    fn line(&mut self, v: &impl serde::Serialize) {
        serde_json::to_writer(&mut self.0, v).unwrap();
        self.0.write_all(b"\n").unwrap();
    }
}

impl Drop for RunLog {
    fn drop(&mut self) {
        // Written whole before the test reads it.
        self.0.flush().unwrap();
    }
}

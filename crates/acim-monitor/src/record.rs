//! CSV recording of every sample received. The recorder belongs to the monitor, not to
//! the link, so a cable pull leaves a gap in `seq` and `period` and the file goes on.

use crate::app::Row;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

/// The CSV header. Values are the frames' decoded values in SI units and rpm, printed in
/// Rust's shortest round-trip form (the frame's resolution: 0.1 rpm, 1 mA, 1 mN m,
/// 1 mohm, 1 mWb, 0.1 V); `period`, `i_d_ref_a` and `i_q_ref_a` are empty when the board
/// sends no `$X` frame.
pub const HEADER: &str = "time_s,seq,period,state,fault,speed_ref_rpm,speed_est_rpm,plant_speed_rpm,i_d_a,i_q_a,i_d_ref_a,i_q_ref_a,torque_nm,load_torque_nm,rs_ohm,flux_wb,dc_bus_v,cycles_min,cycles_mean,cycles_max";

/// An open recording.
pub struct Recorder {
    path: PathBuf,
    out: BufWriter<File>,
    rows: u64,
}

impl Recorder {
    /// Creates (truncates) `path` and writes the header.
    pub fn create(path: PathBuf) -> io::Result<Recorder> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)?;
        }
        let mut out = BufWriter::new(File::create(&path)?);
        writeln!(out, "{HEADER}")?;
        Ok(Recorder { path, out, rows: 0 })
    }

    /// Appends one sample.
    pub fn write(&mut self, r: &Row) -> io::Result<()> {
        let t = &r.t;
        let (period, idr, iqr) = match r.x {
            Some(x) => (
                x.period.to_string(),
                x.i_d_ref.to_string(),
                x.i_q_ref.to_string(),
            ),
            None => (String::new(), String::new(), String::new()),
        };
        writeln!(
            self.out,
            "{:.4},{},{period},{},{},{},{},{},{},{},{idr},{iqr},{},{},{},{},{},{},{},{}",
            r.time_s,
            t.seq,
            t.state,
            t.fault,
            t.speed_ref_rpm,
            t.speed_est_rpm,
            t.plant_speed_rpm,
            t.i_d,
            t.i_q,
            t.torque,
            t.load_torque,
            t.rs,
            t.flux,
            t.dc_bus,
            t.cycles_min,
            t.cycles_mean,
            t.cycles_max
        )?;
        self.rows += 1;
        Ok(())
    }

    /// Rows written.
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Writes what is buffered.
    pub fn flush(&mut self) -> io::Result<()> {
        self.out.flush()
    }

    /// Flushes and closes; returns the path.
    pub fn finish(mut self) -> io::Result<PathBuf> {
        self.out.flush()?;
        Ok(self.path)
    }
}

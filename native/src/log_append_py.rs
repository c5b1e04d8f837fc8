//! camdirector._native.append_log: DirectoryStore.append's write (worker/checkpoint_stores.py) in
//! one call: whether the log is still this process's (the file still linked: a restore elsewhere
//! replaced it), then the entry's length (4 bytes, big-endian) and the entry in one write, the
//! bytes the Python store writes.

use std::fs::File;
use std::io::Write;
use std::mem::ManuallyDrop;
use std::os::unix::fs::MetadataExt;
use std::os::unix::io::FromRawFd;

use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;

/// append_log(fd, entry) -> bool: False, writing nothing, when the file open as fd (a log opened
/// O_APPEND) has no link left; else appends len(entry) as 4 big-endian bytes and entry, in one
/// write, and answers True. OSError when fstat or the write fails (a short write included);
/// ValueError for an entry of 4 GiB or more.
#[pyfunction]
fn append_log(fd: i32, entry: &[u8]) -> PyResult<bool> {
    let length = u32::try_from(entry.len()).map_err(|_| {
        PyValueError::new_err(format!(
            "an entry of {} bytes is too long for the log",
            entry.len()
        ))
    })?;
    // The caller owns fd: borrowed here, never closed.
    let file = ManuallyDrop::new(unsafe { File::from_raw_fd(fd) });
    if file
        .metadata()
        .map_err(|e| PyOSError::new_err(e.to_string()))?
        .nlink()
        == 0
    {
        return Ok(false);
    }
    let mut record = Vec::with_capacity(4 + entry.len());
    record.extend_from_slice(&length.to_be_bytes());
    record.extend_from_slice(entry);
    let written = (&*file)
        .write(&record)
        .map_err(|e| PyOSError::new_err(e.to_string()))?;
    if written != record.len() {
        return Err(PyOSError::new_err(format!(
            "wrote {written} of {} bytes",
            record.len()
        )));
    }
    Ok(true)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(append_log, m)?)
}

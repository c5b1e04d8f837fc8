//! camdirector._native: the compiled frame path (issue 43, docs/frame_path.md). Python stays the
//! reference: every function here has a pure-Python twin it is tested against.

use pyo3::prelude::*;

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}

//! camdirector._native: the compiled frame path (issue 43, docs/frame_path.md). Python stays the
//! reference: every function here has a pure-Python twin it is tested against.

use pyo3::prelude::*;

mod amap;
mod amap_py;
mod bvh;
mod bvh_py;
mod carry;
mod carry_py;
mod deoccluder;
mod deoccluder_py;
mod edge;
mod edge_py;
mod framing;
mod idle_resets;
mod log_append_py;
mod maps;
mod maps_py;
mod motion;
mod move_scene_py;
mod prediction;
mod prediction_py;
mod rotation;
mod scene;
mod scene_py;
mod search;
mod search_frame_py;
mod search_py;
mod stages_py;
mod style_mask;
mod toric;
mod toric_frame_py;
mod toric_py;
mod wire;
mod wire_py;
mod zmq_edge;

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    toric_py::register(m)?;
    bvh_py::register(m)?;
    stages_py::register(m)?;
    scene_py::register(m)?;
    wire_py::register(m)?;
    carry_py::register(m)?;
    search_py::register(m)?;
    prediction_py::register(m)?;
    maps_py::register(m)?;
    deoccluder_py::register(m)?;
    move_scene_py::register(m)?;
    log_append_py::register(m)?;
    toric_frame_py::register(m)?;
    search_frame_py::register(m)?;
    edge_py::register(m)?;
    amap_py::register(m)?;
    Ok(())
}

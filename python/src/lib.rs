//! `lucerna._native`: the lucerna library for Python. `lucerna/__init__.py` wraps it;
//! every function here calls the same library entry points as the command line
//! (`lucerna::job::run`, `lucerna::commands`, `lucerna::cli::main_with`).

use lucerna::film::aov::Aov;
use lucerna::job::RenderJob;
use numpy::{PyArray1, PyArrayMethods};
use pyo3::exceptions::{PyKeyboardInterrupt, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::ffi::OsString;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// A lucerna error as a Python exception: bad input (exit code 2) is a ValueError, the
/// rest a RuntimeError; the message is lucerna's `FILE: ELEMENT: REASON`.
fn to_python(e: lucerna::Error) -> PyErr {
    if e.exit_code() == 2 {
        PyValueError::new_err(e.to_string())
    } else {
        PyRuntimeError::new_err(e.to_string())
    }
}

/// The film's layers as `{name: float32 array (height, width, channels)}`; the beauty is
/// `beauty` (RGBA), the denoised beauty `denoised` (RGB).
fn layers<'py>(py: Python<'py>, rendered: &lucerna::job::Rendered) -> PyResult<Bound<'py, PyDict>> {
    let dict = PyDict::new(py);
    let Some(film) = &rendered.film else {
        return Ok(dict);
    };
    let (w, h) = (film.width as usize, film.height as usize);
    let add = |name: &str, planes: Vec<&[f32]>| -> PyResult<()> {
        let pixels = lucerna::film::planes::interleave(&planes);
        let array = PyArray1::from_vec(py, pixels).reshape([h, w, planes.len()])?;
        dict.set_item(name, array)
    };
    for aov in film.aovs.iter() {
        let planes = film.planes(aov);
        let name = if aov == Aov::Beauty {
            "beauty".to_string()
        } else {
            film.aovs
                .channel_names(aov)
                .first()
                .and_then(|n| n.rsplit_once('.').map(|(layer, _)| layer.to_string()))
                .unwrap_or_else(|| aov.name().to_string())
        };
        add(&name, planes.iter().map(Vec::as_slice).collect())?;
    }
    if let Some(d) = &rendered.denoised {
        add("denoised", d.iter().map(Vec::as_slice).collect())?;
    }
    Ok(dict)
}

/// Renders a scene; `settings` are the command line's options as `(key, value)` string
/// pairs (keys as the flags without `--`). Returns a list of `(layers, stats, outputs)`,
/// one per rendered view. Ctrl-C stops the render (what was sampled is returned, with
/// `stats["interrupted"]` true) and then raises KeyboardInterrupt.
#[pyfunction]
#[pyo3(signature = (scene, settings, write_files))]
fn render<'py>(
    py: Python<'py>,
    scene: Option<PathBuf>,
    settings: Vec<(String, String)>,
    write_files: bool,
) -> PyResult<Bound<'py, PyList>> {
    let mut job = RenderJob {
        scene,
        write_files,
        keep_images: true,
        ..RenderJob::default()
    };
    // The progress bar draws only on a terminal; notebooks get no lines unless asked.
    job.progress = "bar".into();
    for (key, value) in &settings {
        job.set(key, value)
            .map_err(|e| PyValueError::new_err(format!("{key}: {e}")))?;
    }
    let stop = Arc::new(AtomicBool::new(false));
    job.stop = Some(stop.clone());
    // The render runs on its own thread without the GIL; this thread answers Python's
    // signals (Ctrl-C) by stopping it.
    let handle = std::thread::spawn(move || lucerna::job::run(&job));
    let mut interrupted = None;
    while !handle.is_finished() {
        if let Err(e) = py.check_signals() {
            stop.store(true, Ordering::Relaxed);
            interrupted.get_or_insert(e);
        }
        py.detach(|| std::thread::sleep(std::time::Duration::from_millis(20)));
    }
    let outcome = handle
        .join()
        .map_err(|_| PyRuntimeError::new_err("the render panicked"))?
        .map_err(to_python)?;
    if let Some(e) = interrupted
        && outcome.rendered.is_empty()
    {
        return Err(e);
    }
    let list = PyList::empty(py);
    for rendered in &outcome.rendered {
        let s = &rendered.stats;
        let stats = PyDict::new(py);
        stats.set_item("spp", s.spp)?;
        stats.set_item("samples", s.samples)?;
        stats.set_item("seconds", s.seconds)?;
        stats.set_item("rays_closest", s.rays.closest)?;
        stats.set_item("rays_shadow", s.rays.shadow)?;
        stats.set_item("nan_inf_discarded", s.discarded)?;
        stats.set_item("interrupted", s.interrupted || stop.load(Ordering::Relaxed))?;
        stats.set_item("frame", rendered.frame)?;
        stats.set_item("camera", rendered.camera.clone())?;
        let outputs: Vec<String> = rendered
            .outputs
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        list.append((layers(py, rendered)?, stats, outputs))?;
    }
    if stop.load(Ordering::Relaxed) {
        // The caller gets the images through the exception's args.
        return Err(PyKeyboardInterrupt::new_err((
            "render stopped",
            list.unbind(),
        )));
    }
    Ok(list)
}

/// `lucerna inspect`'s report of a scene.
#[pyfunction]
#[pyo3(signature = (scene, settings))]
fn inspect(scene: PathBuf, settings: Vec<(String, String)>) -> PyResult<String> {
    let mut job = RenderJob::default();
    let (mut aov, mut plan) = (None, None);
    for (key, value) in &settings {
        match key.as_str() {
            "aov" => aov = Some(value.clone()),
            "plan" => plan = Some(value.clone()),
            _ => job
                .set(key, value)
                .map_err(|e| PyValueError::new_err(format!("{key}: {e}")))?,
        }
    }
    lucerna::commands::inspect(&scene, &job.load, aov.as_deref(), plan.as_deref())
        .map_err(to_python)
}

/// `lucerna merge`.
#[pyfunction]
fn merge(inputs: Vec<PathBuf>, output: PathBuf) -> PyResult<()> {
    lucerna::commands::merge(&inputs, &output).map_err(to_python)
}

/// `lucerna denoise`.
#[pyfunction]
#[pyo3(signature = (input, output=None))]
fn denoise(input: PathBuf, output: Option<PathBuf>) -> PyResult<()> {
    lucerna::commands::denoise(&input, output.as_deref()).map_err(to_python)
}

/// `lucerna convert`.
#[pyfunction]
#[pyo3(signature = (scene, output, settings))]
fn convert(scene: PathBuf, output: PathBuf, settings: Vec<(String, String)>) -> PyResult<()> {
    let mut job = RenderJob::default();
    for (key, value) in &settings {
        job.set(key, value)
            .map_err(|e| PyValueError::new_err(format!("{key}: {e}")))?;
    }
    lucerna::commands::convert(&scene, &output, &job.load).map_err(to_python)
}

/// The `lucerna` command line with `argv` (program name first); `command` runs it again
/// (for batch children). Returns the exit code.
#[pyfunction]
fn cli(py: Python<'_>, argv: Vec<OsString>, command: Vec<OsString>) -> u8 {
    py.detach(|| lucerna::cli::main_with(argv, &command))
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    lucerna::logging::init(log::LevelFilter::Info, false);
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(render, m)?)?;
    m.add_function(wrap_pyfunction!(inspect, m)?)?;
    m.add_function(wrap_pyfunction!(merge, m)?)?;
    m.add_function(wrap_pyfunction!(denoise, m)?)?;
    m.add_function(wrap_pyfunction!(convert, m)?)?;
    m.add_function(wrap_pyfunction!(cli, m)?)?;
    Ok(())
}

//! The core's errors as Python exceptions: one mapping onto the hierarchy declared in
//! `physcore/_errors.py`.
use crate::error::Error;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// Maps the core's error enum onto the Python hierarchy defined in `physcore/_errors.py`.
pub(super) fn to_py(py: Python<'_>, e: Error) -> PyErr {
    let msg = e.to_string();
    let build = || -> PyResult<PyErr> {
        let errors = py.import("physcore._errors")?;
        Ok(match e {
            Error::InvalidInput { .. } => {
                PyErr::from_value(errors.getattr("InvalidInputError")?.call1((msg.clone(),))?)
            }
            Error::InvalidType { .. } => PyErr::from_value(errors.getattr("InvalidTypeError")?.call1((msg.clone(),))?),
            Error::Interrupted { .. } => pyo3::exceptions::PyKeyboardInterrupt::new_err(msg.clone()),
            Error::Device { .. } => PyErr::from_value(errors.getattr("DeviceError")?.call1((msg.clone(),))?),
            Error::Threads { .. } => PyErr::from_value(errors.getattr("ThreadPoolError")?.call1((msg.clone(),))?),
            Error::OutOfMemory { bytes, .. } => {
                PyErr::from_value(errors.getattr("OutOfMemoryError")?.call1((msg.clone(), bytes))?)
            }
            Error::Diverged { step, t, particle, quantity, suggested_dt, rolled_back_to, .. } => {
                let exc = errors.getattr("SimulationDiverged")?.call1((
                    msg.clone(),
                    step,
                    t,
                    particle,
                    quantity.as_str(),
                    suggested_dt,
                    rolled_back_to,
                ))?;
                PyErr::from_value(exc)
            }
        })
    };
    build().unwrap_or_else(|_| PyValueError::new_err(msg))
}

/// `to_py` where no `Python` token is at hand (the GIL is held: we are inside a call).
pub(super) fn err(e: Error) -> PyErr {
    Python::attach(|py| to_py(py, e))
}

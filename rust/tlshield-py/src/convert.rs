//! numpy <-> slices. Inputs are accepted as any array-like of numbers; contiguous float64 arrays
//! are read in place, anything else is converted once.

use std::borrow::Cow;

use numpy::{AllowTypeChange, PyArray1, PyArrayLikeDyn, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;

/// A float64 array of known dimensionality, borrowed from Python.
pub struct FloatArray<'py> {
    array: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
}

impl<'py> FloatArray<'py> {
    /// Extracts `obj` as a float64 array with `ndim` dimensions; `name` and `layout` (e.g.
    /// "(T+1, n)") are used in the error message.
    pub fn extract(
        obj: &Bound<'py, PyAny>,
        name: &str,
        ndim: usize,
        layout: &str,
    ) -> PyResult<Self> {
        if obj.is_none() {
            return Err(PyTypeError::new_err(format!(
                "{name}: expected an array-like of numbers with shape {layout}, got None"
            )));
        }
        let array: PyArrayLikeDyn<'py, f64, AllowTypeChange> = obj.extract().map_err(|e| {
            PyTypeError::new_err(format!(
                "{name}: expected an array-like of numbers with shape {layout}, got {} ({e})",
                obj.get_type()
                    .name()
                    .map_or_else(|_| "?".into(), |n| n.to_string())
            ))
        })?;
        if array.ndim() != ndim {
            return Err(PyValueError::new_err(format!(
                "{name}: expected a {ndim}-D array of shape {layout}, got shape {}",
                shape_text(array.shape())
            )));
        }
        Ok(FloatArray { array })
    }

    /// The shape.
    pub fn shape(&self) -> &[usize] {
        self.array.shape()
    }

    /// The values in C order, borrowed when the array is C-contiguous.
    pub fn values(&self) -> Cow<'_, [f64]> {
        match self.array.as_slice() {
            Ok(slice) => Cow::Borrowed(slice),
            Err(_) => Cow::Owned(self.array.as_array().iter().copied().collect()),
        }
    }
}

/// A single state-sized vector `(n,)` for the per-step calls. A contiguous float64 numpy
/// array is copied straight out (a few dozen bytes; cheaper than registering a borrow with
/// numpy's borrow checker); anything else goes through [`FloatArray::extract`].
pub fn vector(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<f64>> {
    if let Ok(array) = obj.cast::<PyArray1<f64>>() {
        if let Ok(values) = array.to_vec() {
            return Ok(values);
        }
    }
    Ok(FloatArray::extract(obj, name, 1, "(n,)")?
        .values()
        .into_owned())
}

/// Extracts a list of non-negative dimension indices, naming the bad entry.
pub fn indices(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<usize>> {
    let raw: Vec<i64> = obj.extract().map_err(|_| {
        PyTypeError::new_err(format!(
            "{name}: expected a sequence of integer dimension indices"
        ))
    })?;
    raw.iter()
        .enumerate()
        .map(|(i, &d)| {
            usize::try_from(d).map_err(|_| {
                PyValueError::new_err(format!(
                    "{name}[{i}] = {d} is not a valid dimension index (must be >= 0)"
                ))
            })
        })
        .collect()
}

/// A shape as Python prints it: `(3,)`, `(2, 4)`, `()`.
pub fn shape_text(shape: &[usize]) -> String {
    match shape {
        [one] => format!("({one},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(|d| d.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

//! numpy <-> slices. Inputs are accepted as any array-like of real numbers in any layout (C or
//! Fortran order, strided, negative strides, read-only, float32 or integer): C-contiguous float64
//! arrays are read in place, anything else is converted once into C order. Complex, boolean,
//! object and text input is refused with a `TypeError` naming the argument (numpy would drop an
//! imaginary part or read `True` as 1 without a word).

use numpy::{
    AllowTypeChange, PyArray1, PyArrayDescrMethods, PyArrayLike1, PyArrayLikeDyn, PyArrayMethods,
    PyUntypedArray, PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyOverflowError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyFloat};
use tlshield_core::Automaton;

use crate::errors::{map, AutomatonError};

/// numpy's dtype kind of `obj`: its own for an ndarray, else that of `numpy.asarray(obj)`.
fn dtype_kind(obj: &Bound<'_, PyAny>) -> PyResult<u8> {
    if let Ok(array) = obj.cast::<PyUntypedArray>() {
        return Ok(array.dtype().kind());
    }
    let array = obj.py().import("numpy")?.call_method1("asarray", (obj,))?;
    Ok(array.cast::<PyUntypedArray>()?.dtype().kind())
}

/// The dtype kinds read as numbers: signed and unsigned integers and floats.
fn check_real(obj: &Bound<'_, PyAny>, name: &str, layout: &str) -> PyResult<()> {
    let kind = match dtype_kind(obj) {
        Ok(kind) => kind,
        // numpy could not make an array of it (ragged lists...): the extraction says why.
        Err(_) => return Ok(()),
    };
    let what = match kind {
        b'f' | b'i' | b'u' => return Ok(()),
        b'c' => "complex numbers (the imaginary part would be lost)",
        b'b' => "booleans",
        b'O' => "Python objects",
        b'U' | b'S' => "text",
        _ => "values that are not real numbers",
    };
    Err(PyTypeError::new_err(format!(
        "{name}: expected real numbers (float or int) with shape {layout}, got an array of {what}"
    )))
}

/// A float64 array of known dimensionality, borrowed from Python (with its C-order copy when
/// it is not C-contiguous: made once, through a checked allocation).
pub struct FloatArray<'py> {
    array: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
    copy: Option<Vec<f64>>,
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
        check_real(obj, name, layout)?;
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
        let copy = if array.is_c_contiguous() && array.as_slice().is_ok() {
            None
        } else {
            // A strided or broadcast view (np.broadcast_to) can name far more values than
            // memory holds: the copy asks the allocator first and names the argument.
            let mut copy = map(tlshield_core::alloc::try_with_capacity(name, array.len()))?;
            copy.extend(array.as_array().iter().copied());
            Some(copy)
        };
        Ok(FloatArray { array, copy })
    }

    /// The shape.
    pub fn shape(&self) -> &[usize] {
        self.array.shape()
    }

    /// The values in C order, borrowed from numpy when the array is C-contiguous, else from
    /// the copy made at extraction. (`as_slice` alone would also hand out a
    /// Fortran-contiguous buffer, in Fortran order.)
    pub fn values(&self) -> &[f64] {
        match &self.copy {
            Some(copy) => copy,
            None => self.array.as_slice().unwrap_or_default(),
        }
    }
}

/// A sequence argument as a vector of `item(element)`, its length checked against memory
/// first: PyO3's own `Vec` extraction reserves `len()` elements unchecked, so an object that
/// claims more than memory holds (`range(10**12)`, a broadcast view) would abort the process.
pub fn sequence_with<'py, T>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    mut item: impl FnMut(usize, Bound<'py, PyAny>) -> PyResult<T>,
) -> PyResult<Vec<T>> {
    let not_a_sequence = || {
        PyTypeError::new_err(format!(
            "{name}: expected a sequence, got {}",
            type_name(obj)
        ))
    };
    if obj.is_instance_of::<pyo3::types::PyString>() {
        return Err(not_a_sequence());
    }
    let iter = obj.try_iter().map_err(|_| not_a_sequence())?;
    let mut out = map(tlshield_core::alloc::try_with_capacity(
        name,
        obj.len().unwrap_or(0),
    ))?;
    for (i, element) in iter.enumerate() {
        out.push(item(i, element?)?);
    }
    Ok(out)
}

/// [`sequence_with`] extracting each element as `T`; a wrong element is a `TypeError` naming
/// `name[i]`.
pub fn sequence<'py, T>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<Vec<T>>
where
    T: pyo3::conversion::FromPyObjectOwned<'py>,
{
    sequence_with(obj, name, |i, element| {
        element
            .extract::<T>()
            .map_err(|e| PyTypeError::new_err(format!("{name}[{i}]: {}", Into::<PyErr>::into(e))))
    })
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
    Ok(FloatArray::extract(obj, name, 1, "(n,)")?.values().to_vec())
}

/// An FSA state argument: a Python or numpy integer in `0..automaton.num_states()`; a bool, a
/// float or an integer out of range (however large) is refused, naming `name`.
pub fn state(obj: &Bound<'_, PyAny>, name: &str, automaton: &Automaton) -> PyResult<usize> {
    if obj.is_instance_of::<PyBool>() || obj.is_instance_of::<PyFloat>() {
        return Err(PyTypeError::new_err(format!(
            "{name}: expected an integer FSA state, got {}",
            type_name(obj)
        )));
    }
    match obj.extract::<i64>() {
        // A negative id is no usize: refused here, in the words the core uses for the rest.
        Ok(q) => match usize::try_from(q) {
            Ok(q) => map(automaton.check_state(name, q)),
            Err(_) => Err(no_such_state(name, q, automaton)),
        },
        Err(e) if e.is_instance_of::<PyOverflowError>(obj.py()) => Err(no_such_state(
            name,
            obj.repr().map_or_else(|_| "?".into(), |r| r.to_string()),
            automaton,
        )),
        Err(_) => Err(PyTypeError::new_err(format!(
            "{name}: expected an integer FSA state, got {}",
            type_name(obj)
        ))),
    }
}

/// A `(B,)` array-like of FSA states (any integer dtype and layout) as ids; the core function
/// they are passed to checks that each exists. Anything but integers is a `TypeError` naming
/// `name`.
pub fn states(obj: &Bound<'_, PyAny>, name: &str, automaton: &Automaton) -> PyResult<Vec<usize>> {
    let kind = dtype_kind(obj).map_err(|_| states_type_error(obj, name))?;
    if is_empty_list(obj) {
        return Ok(Vec::new());
    }
    if kind != b'i' && kind != b'u' {
        return Err(states_type_error(obj, name));
    }
    // Only converted here (a negative id is no usize): the core call that takes the ids
    // checks that each exists, naming it as `{name}[i]`. The ids go into a checked allocation:
    // a broadcast view can name more of them than memory holds.
    fn ids<T: Copy + std::fmt::Display>(
        values: numpy::ndarray::ArrayView1<'_, T>,
        name: &str,
        automaton: &Automaton,
        to_usize: impl Fn(T) -> Option<usize>,
    ) -> PyResult<Vec<usize>> {
        let mut out = map(tlshield_core::alloc::try_with_capacity(name, values.len()))?;
        for (i, &q) in values.iter().enumerate() {
            let id =
                to_usize(q).ok_or_else(|| no_such_state(&format!("{name}[{i}]"), q, automaton))?;
            out.push(id);
        }
        Ok(out)
    }
    let shape_error =
        |e: PyErr| PyValueError::new_err(format!("{name}: expected shape (B,) ({e})"));
    if kind == b'u' {
        let qs: PyArrayLike1<'_, u64, AllowTypeChange> = obj.extract().map_err(shape_error)?;
        return ids(qs.as_array(), name, automaton, |q| usize::try_from(q).ok());
    }
    let qs: PyArrayLike1<'_, i64, AllowTypeChange> = obj.extract().map_err(shape_error)?;
    ids(qs.as_array(), name, automaton, |q| usize::try_from(q).ok())
}

/// The error of an FSA state id that no usize holds (negative, or past u64), worded as the
/// core words an id past the last state.
fn no_such_state(name: &str, shown: impl std::fmt::Display, automaton: &Automaton) -> PyErr {
    AutomatonError::new_err(format!(
        "{name}: state {shown} does not exist (the automaton has states 0..{})",
        automaton.num_states()
    ))
}

fn states_type_error(obj: &Bound<'_, PyAny>, name: &str) -> PyErr {
    let dtype = obj
        .getattr("dtype")
        .and_then(|d| d.str())
        .map_or_else(|_| type_name(obj), |d| format!("dtype {d}"));
    PyTypeError::new_err(format!(
        "{name}: expected integer FSA states with shape (B,), got {dtype}"
    ))
}

fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type()
        .name()
        .map_or_else(|_| "?".into(), |n| n.to_string())
}

/// Extracts a list of non-negative dimension indices, naming the bad entry.
pub fn indices(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<usize>> {
    let raw: Vec<i64> = sequence(obj, name).map_err(|e| {
        if e.is_instance_of::<pyo3::exceptions::PyMemoryError>(obj.py()) {
            return e;
        }
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

/// A `(k,)` array-like of row indices of a batch (any integer dtype); a negative index is a
/// `ValueError` naming `name[i]` (the core checks the upper bound).
pub fn row_indices(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<usize>> {
    let kind = dtype_kind(obj).map_err(|_| states_type_error(obj, name))?;
    if is_empty_list(obj) {
        return Ok(Vec::new());
    }
    if kind != b'i' && kind != b'u' {
        return Err(PyTypeError::new_err(format!(
            "{name}: expected integer row indices, got {}",
            type_name(obj)
        )));
    }
    let rows: PyArrayLike1<'_, i64, AllowTypeChange> = obj
        .extract()
        .map_err(|e| PyValueError::new_err(format!("{name}: expected shape (k,) ({e})")))?;
    let rows = rows.as_array();
    let mut out = map(tlshield_core::alloc::try_with_capacity(name, rows.len()))?;
    for (i, &r) in rows.iter().enumerate() {
        out.push(usize::try_from(r).map_err(|_| {
            PyValueError::new_err(format!("{name}[{i}] = {r}: expected a row index >= 0"))
        })?);
    }
    Ok(out)
}

/// Whether `obj` is an empty list or tuple: numpy reads `[]` as float64, but as ids it is
/// an empty batch's.
fn is_empty_list(obj: &Bound<'_, PyAny>) -> bool {
    (obj.is_instance_of::<pyo3::types::PyList>() || obj.is_instance_of::<pyo3::types::PyTuple>())
        && obj.len().is_ok_and(|n| n == 0)
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

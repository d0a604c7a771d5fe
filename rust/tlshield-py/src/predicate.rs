//! `Halfspace`, `Ball`, `Union` and `Intersection`: Python classes around
//! `tlshield_core::Predicate`.

use numpy::{IntoPyArray, PyArray1};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyList, PyTuple};
use tlshield_core::{Center, Offset, Predicate};

use crate::convert::{indices, FloatArray};
use crate::errors::map;
use crate::pickling::reduce;

fn state<'py>(obj: &Bound<'py, PyAny>) -> PyResult<FloatArray<'py>> {
    FloatArray::extract(obj, "s", 1, "(n,)")
}

fn value(p: &Predicate, s: &Bound<'_, PyAny>) -> PyResult<f64> {
    map(p.robustness(state(s)?.values()))
}

fn gradient<'py>(p: &Predicate, s: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<f64>>> {
    Ok(map(p.gradient(state(s)?.values()))?.into_pyarray(s.py()))
}

fn fmt_list<T: std::fmt::Debug>(v: &[T]) -> String {
    format!("{v:?}")
}

/// Half-space predicate `rho(s) = w . s + b` (holds iff > 0).
#[pyclass(name = "Halfspace", module = "tlshield._core", frozen)]
pub struct PyHalfspace {
    pub(crate) inner: Predicate,
}

#[pymethods]
impl PyHalfspace {
    #[new]
    fn new(w: &Bound<'_, PyAny>, b: f64) -> PyResult<Self> {
        let w = FloatArray::extract(w, "w", 1, "(n,)")?.values().to_vec();
        Ok(PyHalfspace {
            inner: map(Predicate::halfspace(w, b))?,
        })
    }

    /// Robustness `w . s + b` at state `s`.
    fn robustness(&self, s: &Bound<'_, PyAny>) -> PyResult<f64> {
        value(&self.inner, s)
    }

    /// Gradient of the robustness at `s` (equals `w`).
    fn gradient<'py>(&self, s: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        gradient(&self.inner, s)
    }

    /// The normal vector.
    #[getter]
    fn w<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.halfspace().w().to_vec().into_pyarray(py)
    }

    /// The offset.
    #[getter]
    fn b(&self) -> f64 {
        self.halfspace().b()
    }

    fn __repr__(&self) -> String {
        let h = self.halfspace();
        format!("Halfspace(w={}, b={:?})", fmt_list(h.w()), h.b())
    }

    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        let h = slf.get().halfspace();
        let args = PyTuple::new(
            py,
            [
                h.w().to_vec().into_pyobject(py)?.into_any(),
                h.b().into_pyobject(py)?.into_any(),
            ],
        )?;
        reduce(slf.get_type().into_any(), args, None, None)
    }
}

impl PyHalfspace {
    fn halfspace(&self) -> &tlshield_core::Halfspace {
        match &self.inner {
            Predicate::Halfspace(h) => h,
            _ => unreachable!("PyHalfspace always wraps a half-space"),
        }
    }
}

/// Ball predicate `rho(s) = radius - |s[pos] - c|` with a fixed centre `center` or a centre read
/// from the state dimensions `center_dims` (give exactly one). With `heading` and `offset`, the
/// point held is a point of the body: `s[pos] + R(s[heading]) offset`, `offset = (along,
/// across)` in metres ahead of and left of `s[pos]`.
#[pyclass(name = "Ball", module = "tlshield._core", frozen)]
pub struct PyBall {
    pub(crate) inner: Predicate,
}

#[pymethods]
impl PyBall {
    #[new]
    #[pyo3(signature = (pos, radius, center=None, center_dims=None, heading=None, offset=None))]
    fn new(
        pos: &Bound<'_, PyAny>,
        radius: f64,
        center: Option<&Bound<'_, PyAny>>,
        center_dims: Option<&Bound<'_, PyAny>>,
        heading: Option<usize>,
        offset: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let pos = indices(pos, "pos")?;
        let center = match (center, center_dims) {
            (Some(c), None) => {
                Center::Fixed(FloatArray::extract(c, "center", 1, "(len(pos),)")?.values().to_vec())
            }
            (None, Some(d)) => Center::Dims(indices(d, "center_dims")?),
            (None, None) => {
                return Err(PyValueError::new_err(
                    "Ball needs a centre: pass center=[...] (fixed) or center_dims=[...] (read from the state)",
                ))
            }
            (Some(_), Some(_)) => {
                return Err(PyValueError::new_err(
                    "Ball takes center or center_dims, not both",
                ))
            }
        };
        let inner = match (heading, offset) {
            (None, None) => Predicate::ball(pos, radius, center),
            (Some(heading), Some(o)) => {
                let o = FloatArray::extract(o, "offset", 1, "(2,): (along, across)")?;
                let [along, across] = o.values()[..] else {
                    return Err(PyValueError::new_err(format!(
                        "offset: expected 2 values (along, across), got {}",
                        o.values().len()
                    )));
                };
                let offset = Offset {
                    heading,
                    along,
                    across,
                };
                Predicate::body_ball(pos, radius, center, offset)
            }
            _ => {
                return Err(PyValueError::new_err(
                    "Ball takes heading and offset together (a point of the body), or neither",
                ))
            }
        };
        Ok(PyBall { inner: map(inner)? })
    }

    /// Robustness `radius - |s[pos] - c|` at state `s`.
    fn robustness(&self, s: &Bound<'_, PyAny>) -> PyResult<f64> {
        value(&self.inner, s)
    }

    /// Gradient of the robustness at `s` (zero at the centre).
    fn gradient<'py>(&self, s: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        gradient(&self.inner, s)
    }

    /// State dimensions of the point that must be inside.
    #[getter]
    fn pos(&self) -> Vec<usize> {
        self.ball().pos().to_vec()
    }

    /// The radius.
    #[getter]
    fn radius(&self) -> f64 {
        self.ball().radius()
    }

    /// The fixed centre, or None when it is read from the state.
    #[getter]
    fn center(&self) -> Option<Vec<f64>> {
        match self.ball().center() {
            Center::Fixed(c) => Some(c.clone()),
            Center::Dims(_) => None,
        }
    }

    /// The state dimensions holding the centre, or None for a fixed centre.
    #[getter]
    fn center_dims(&self) -> Option<Vec<usize>> {
        match self.ball().center() {
            Center::Fixed(_) => None,
            Center::Dims(d) => Some(d.clone()),
        }
    }

    /// The heading's state dimension of a body point, or None.
    #[getter]
    fn heading(&self) -> Option<usize> {
        self.ball().offset().map(|o| o.heading)
    }

    /// A body point's `(along, across)` offset from `s[pos]`, or None.
    #[getter]
    fn offset(&self) -> Option<(f64, f64)> {
        self.ball().offset().map(|o| (o.along, o.across))
    }

    fn __repr__(&self) -> String {
        let b = self.ball();
        let centre = match b.center() {
            Center::Fixed(c) => format!("center={}", fmt_list(c)),
            Center::Dims(d) => format!("center_dims={}", fmt_list(d)),
        };
        let body = match b.offset() {
            Some(o) => format!(
                ", heading={}, offset=({:?}, {:?})",
                o.heading, o.along, o.across
            ),
            None => String::new(),
        };
        format!(
            "Ball(pos={}, radius={:?}, {centre}{body})",
            fmt_list(b.pos()),
            b.radius()
        )
    }

    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        let b = slf.get().ball();
        let none = py.None().into_bound(py);
        let (center, dims) = match b.center() {
            Center::Fixed(c) => (c.clone().into_pyobject(py)?.into_any(), none),
            Center::Dims(d) => (none, d.clone().into_pyobject(py)?.into_any()),
        };
        let args = PyTuple::new(
            py,
            [
                b.pos().to_vec().into_pyobject(py)?.into_any(),
                b.radius().into_pyobject(py)?.into_any(),
                center,
                dims,
                b.offset().map(|o| o.heading).into_pyobject(py)?.into_any(),
                b.offset()
                    .map(|o| (o.along, o.across))
                    .into_pyobject(py)?
                    .into_any(),
            ],
        )?;
        reduce(slf.get_type().into_any(), args, None, None)
    }
}

impl PyBall {
    fn ball(&self) -> &tlshield_core::Ball {
        match &self.inner {
            Predicate::Ball(b) => b,
            _ => unreachable!("PyBall always wraps a ball"),
        }
    }
}

/// Wraps a core predicate in the matching Python class.
pub fn to_python<'py>(py: Python<'py>, p: &Predicate) -> PyResult<Bound<'py, PyAny>> {
    let inner = p.clone();
    Ok(match p {
        Predicate::Halfspace(_) => Bound::new(py, PyHalfspace { inner })?.into_any(),
        Predicate::Ball(_) => Bound::new(py, PyBall { inner })?.into_any(),
        Predicate::Union(_) => Bound::new(py, PyUnion { inner })?.into_any(),
        Predicate::Intersection(_) => Bound::new(py, PyIntersection { inner })?.into_any(),
    })
}

/// A predicate from a Python `Halfspace`, `Ball`, `Union` or `Intersection`, or a list or
/// tuple of them (their union: "red" made of two discs); `what` names it in the error.
pub fn predicate_of(what: &str, value: &Bound<'_, PyAny>) -> PyResult<Predicate> {
    if let Ok(h) = value.cast::<PyHalfspace>() {
        return Ok(h.get().inner.clone());
    }
    if let Ok(b) = value.cast::<PyBall>() {
        return Ok(b.get().inner.clone());
    }
    if let Ok(u) = value.cast::<PyUnion>() {
        return Ok(u.get().inner.clone());
    }
    if let Ok(i) = value.cast::<PyIntersection>() {
        return Ok(i.get().inner.clone());
    }
    if value.is_instance_of::<PyList>() || value.is_instance_of::<PyTuple>() {
        return map(Predicate::union(parts_of(what, value)?));
    }
    Err(PyTypeError::new_err(format!(
        "{what}: expected a tlshield.Halfspace, Ball, Union or Intersection (or a list of them, \
         their union), got {}",
        value
            .get_type()
            .name()
            .map_or_else(|_| "?".into(), |n| n.to_string())
    )))
}

fn parts_of(what: &str, parts: &Bound<'_, PyAny>) -> PyResult<Vec<Predicate>> {
    parts
        .try_iter()
        .map_err(|_| PyTypeError::new_err(format!("{what}: expected a sequence of predicates")))?
        .enumerate()
        .map(|(i, p)| predicate_of(&format!("{what}[{i}]"), &p?))
        .collect()
}

macro_rules! region_class {
    ($rust:ident, $py:literal, $ctor:ident, $doc:literal) => {
        #[doc = $doc]
        #[pyclass(name = $py, module = "tlshield._core", frozen)]
        pub struct $rust {
            pub(crate) inner: Predicate,
        }

        #[pymethods]
        impl $rust {
            #[new]
            fn new(parts: &Bound<'_, PyAny>) -> PyResult<Self> {
                Ok($rust {
                    inner: map(Predicate::$ctor(parts_of("parts", parts)?))?,
                })
            }

            /// Robustness at state `s`.
            fn robustness(&self, s: &Bound<'_, PyAny>) -> PyResult<f64> {
                value(&self.inner, s)
            }

            /// Gradient of the robustness at `s`: the deciding part's.
            fn gradient<'py>(&self, s: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<f64>>> {
                gradient(&self.inner, s)
            }

            /// The parts.
            #[getter]
            fn parts<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyAny>>> {
                self.inner
                    .parts()
                    .iter()
                    .map(|p| to_python(py, p))
                    .collect()
            }

            fn __repr__(slf: &Bound<'_, Self>) -> PyResult<String> {
                let parts: Vec<String> = slf
                    .get()
                    .inner
                    .parts()
                    .iter()
                    .map(|p| Ok(to_python(slf.py(), p)?.repr()?.to_string()))
                    .collect::<PyResult<_>>()?;
                Ok(format!("{}([{}])", $py, parts.join(", ")))
            }

            fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
                let py = slf.py();
                let parts = PyList::new(
                    py,
                    slf.get()
                        .inner
                        .parts()
                        .iter()
                        .map(|p| to_python(py, p))
                        .collect::<PyResult<Vec<_>>>()?,
                )?;
                reduce(
                    slf.get_type().into_any(),
                    PyTuple::new(py, [parts])?,
                    None,
                    None,
                )
            }
        }
    };
}

region_class!(
    PyUnion,
    "Union",
    union,
    "A union of regions: holds where any part holds (robustness: the largest part's)."
);
region_class!(
    PyIntersection,
    "Intersection",
    intersection,
    "An intersection of regions: holds where every part holds (robustness: the smallest)."
);

//! `Spec`: a formula with its predicates; robustness of trajectories, single and batched.

use numpy::{IntoPyArray, PyArray1};
use pyo3::exceptions::{PyKeyboardInterrupt, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock, Weak};
use std::time::{Duration, Instant};

use tlshield_core::{Automaton, AutomatonError, Spec, Trajectory, TrajectoryBatch};

use crate::convert::FloatArray;
use crate::errors::map;
use crate::predicate::{predicate_of, to_python};

/// An scTLTL formula over named state predicates.
#[pyclass(name = "Spec", module = "tlshield._core", frozen)]
pub struct PySpec {
    pub(crate) inner: Spec,
    automaton: OnceLock<Arc<Automaton>>,
}

impl PySpec {
    /// Wraps a core spec.
    pub fn from_core(inner: Spec) -> Self {
        PySpec {
            inner,
            automaton: OnceLock::new(),
        }
    }
}

impl PySpec {
    /// The spec's automaton, built on first use and shared afterwards (see [`interned`]).
    pub fn shared_automaton(&self, py: Python<'_>) -> PyResult<Arc<Automaton>> {
        if let Some(aut) = self.automaton.get() {
            return Ok(aut.clone());
        }
        let built = interned(py, &self.inner)?;
        Ok(self.automaton.get_or_init(|| built).clone())
    }
}

/// The live automata by spec (its `Debug` text: the formula, the atoms and the predicates'
/// exact numbers).
static AUTOMATA: Mutex<Option<HashMap<String, Weak<Automaton>>>> = Mutex::new(None);

/// The automaton of `spec`: the one already built for an equal spec while it lives, else a
/// new build. Equal specs share one automaton, so a shield and a monitor unpickled apart (or
/// copied apart) still watch the same automaton: the core checks that by identity.
pub fn interned(py: Python<'_>, spec: &Spec) -> PyResult<Arc<Automaton>> {
    let key = format!("{spec:?}");
    let lookup = |key: &str| {
        let table = AUTOMATA.lock().unwrap_or_else(|e| e.into_inner());
        table.as_ref()?.get(key)?.upgrade()
    };
    if let Some(aut) = lookup(&key) {
        return Ok(aut);
    }
    // Built without the lock (with the GIL released): a concurrent build of the same spec
    // is possible, and the first one stored wins.
    let built = Arc::new(build_responsive(py, spec)?);
    let mut table = AUTOMATA.lock().unwrap_or_else(|e| e.into_inner());
    let table = table.get_or_insert_with(HashMap::new);
    table.retain(|_, aut| aut.strong_count() > 0);
    if let Some(aut) = table.get(&key).and_then(Weak::upgrade) {
        return Ok(aut);
    }
    table.insert(key, Arc::downgrade(&built));
    Ok(built)
}

/// Builds `spec`'s automaton with the GIL released, checking for signals (Ctrl-C) about every
/// 50 ms: an interrupt stops the build and raises ``KeyboardInterrupt`` (or whatever the
/// signal handler raised).
pub fn build_responsive(py: Python<'_>, spec: &Spec) -> PyResult<Automaton> {
    let raised: Mutex<Option<PyErr>> = Mutex::new(None);
    let last_check = Mutex::new(Instant::now());
    let stop = || {
        let mut last = last_check.lock().unwrap_or_else(|e| e.into_inner());
        if last.elapsed() < Duration::from_millis(50) {
            return false;
        }
        *last = Instant::now();
        Python::attach(|py| match py.check_signals() {
            Ok(()) => false,
            Err(err) => {
                *raised.lock().unwrap_or_else(|e| e.into_inner()) = Some(err);
                true
            }
        })
    };
    match py.detach(|| Automaton::build_until(spec, &stop)) {
        Err(AutomatonError::Interrupted) => Err(raised
            .into_inner()
            .unwrap_or_else(|e| e.into_inner())
            .unwrap_or_else(|| {
                PyKeyboardInterrupt::new_err("the automaton build was interrupted")
            })),
        other => map(other),
    }
}

/// Groups of atom names (``exclusive``), each a sequence of names.
pub fn groups_of(obj: &Bound<'_, PyAny>) -> PyResult<Vec<Vec<String>>> {
    crate::convert::sequence_with(obj, "exclusive", |i, group| {
        crate::convert::sequence(&group, &format!("exclusive[{i}]"))
    })
}

fn trajectory<'py>(obj: &Bound<'py, PyAny>) -> PyResult<FloatArray<'py>> {
    FloatArray::extract(obj, "traj", 2, "(T+1, n)")
}

#[pymethods]
impl PySpec {
    #[new]
    #[pyo3(signature = (formula, predicates, exclusive=None))]
    fn new(
        formula: &str,
        predicates: &Bound<'_, PyAny>,
        exclusive: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let items = predicates.call_method0("items").map_err(|_| {
            PyTypeError::new_err(format!(
                "predicates: expected a mapping of atom names to predicates, got {}",
                predicates
                    .get_type()
                    .name()
                    .map_or_else(|_| "?".into(), |n| n.to_string())
            ))
        })?;
        let mut bound = Vec::new();
        for item in items.try_iter()? {
            let (key, value): (Bound<'_, PyAny>, Bound<'_, PyAny>) = item?.extract()?;
            let name: String = key.extract().map_err(|_| {
                PyTypeError::new_err(format!(
                    "predicates: keys must be atom names (str), got {}",
                    key.repr().map_or_else(|_| "?".into(), |r| r.to_string())
                ))
            })?;
            let what = format!("predicates[{}]", key.repr()?);
            let predicate = predicate_of(&what, &value)?;
            bound.push((name, predicate));
        }
        let mut spec = map(Spec::new(formula, bound))?;
        if let Some(groups) = exclusive.map(groups_of).transpose()? {
            spec = map(spec.with_exclusive(groups))?;
        }
        Ok(PySpec::from_core(spec))
    }

    /// Atom names in order of first appearance in the formula.
    #[getter]
    fn atoms(&self) -> Vec<String> {
        self.inner.atoms().to_vec()
    }

    /// The declared exclusive groups, as lists of atom names.
    #[getter]
    fn exclusive(&self) -> Vec<Vec<String>> {
        let atoms = self.inner.atoms();
        self.inner
            .exclusive()
            .iter()
            .map(|&g| {
                (0..atoms.len())
                    .filter(|i| g >> i & 1 == 1)
                    .map(|i| atoms[i].clone())
                    .collect()
            })
            .collect()
    }

    /// The predicates of the atoms, by name.
    #[getter]
    fn predicates<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let dict = PyDict::new(py);
        for (name, p) in self.inner.atoms().iter().zip(self.inner.predicates()) {
            dict.set_item(name, to_python(py, p)?)?;
        }
        Ok(dict)
    }

    /// Robustness of every atom at state `s`, shape (n_atoms,).
    fn atom_robustness<'py>(
        &self,
        py: Python<'py>,
        s: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let s = FloatArray::extract(s, "s", 1, "(n,)")?;
        Ok(map(self.inner.atom_robustness(s.values()))?.into_pyarray(py))
    }

    /// Robustness of the trajectory `traj` (shape (T+1, n)) at t = 0, closed window.
    fn robustness(&self, traj: &Bound<'_, PyAny>) -> PyResult<f64> {
        let arr = trajectory(traj)?;
        let values = arr.values();
        map(self
            .inner
            .robustness(map(Trajectory::new(values, arr.shape()[1]))?))
    }

    /// Whether the trajectory satisfies the formula (Boolean semantics).
    fn satisfied(&self, traj: &Bound<'_, PyAny>) -> PyResult<bool> {
        let arr = trajectory(traj)?;
        let values = arr.values();
        map(self
            .inner
            .satisfied(map(Trajectory::new(values, arr.shape()[1]))?))
    }

    /// Robustness of each trajectory of `trajs` (shape (B, T+1, n)) -> (B,), computed in
    /// parallel with the GIL released.
    fn robustness_batch<'py>(
        &self,
        py: Python<'py>,
        trajs: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let arr = FloatArray::extract(trajs, "trajs", 3, "(B, T+1, n)")?;
        let shape = arr.shape();
        let (b, t, n) = (shape[0], shape[1], shape[2]);
        let values = arr.values();
        let batch = map(TrajectoryBatch::new(values, b, t, n))?;
        let spec = &self.inner;
        let out = py.detach(|| spec.robustness_batch(batch));
        Ok(map(out)?.into_pyarray(py))
    }

    fn __str__(&self) -> String {
        self.inner.to_string()
    }

    fn __repr__(&self) -> String {
        format!(
            "Spec({:?}, atoms={:?})",
            self.inner.to_string(),
            self.inner.atoms()
        )
    }

    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        let this = slf.get();
        let args = PyTuple::new(
            py,
            [
                this.inner.to_string().into_pyobject(py)?.into_any(),
                this.predicates(py)?.into_any(),
                this.exclusive().into_pyobject(py)?.into_any(),
            ],
        )?;
        crate::pickling::reduce(slf.get_type().into_any(), args, None, None)
    }
}

//! `Shield`'s construction (every parameter converted and checked by the core), its getters
//! and repr. Its results live in `shield_results`, its calls in `shield_filter`,
//! `shield_grad` and `shield_pickle`.

use std::sync::Arc;

use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};
use tlshield_core::{Automaton, Bounds, Shield, ShieldParams, SolverChoice};

use crate::automaton::PyAutomaton;
use crate::convert::{self};
use crate::custom::PyControlAffine;
use crate::dynamics::model_of;
use crate::errors::map;
use crate::literals::LiteralNames;
pub use crate::shield_results::{PyFilterBatch, PyFilterResult};
use crate::spec::PySpec;

/// `(a, b)` or `[a, b]` (bounds read back from JSON are lists).
fn pair<'py>(obj: &Bound<'py, PyAny>) -> Option<[Bound<'py, PyAny>; 2]> {
    if obj.is_instance_of::<PyString>() {
        return None;
    }
    // A pair has two items: anything claiming more is not one (and is never copied).
    if obj.len().ok()? != 2 {
        return None;
    }
    let items: Vec<Bound<'py, PyAny>> = convert::sequence(obj, "bounds").ok()?;
    items.try_into().ok()
}

/// Bounds from `(lo, hi)`: two numbers (the same bounds for every input, broadcast by the core
/// once it knows m), or per-input sequences (a number beside a sequence is repeated to its
/// length).
fn bounds(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Bounds> {
    let pair_error = || {
        PyTypeError::new_err(format!(
            "{name}: expected a pair (lo, hi) of numbers or of per-input sequences"
        ))
    };
    let [lo, hi] = pair(obj).ok_or_else(pair_error)?;
    let side = |v: &Bound<'_, PyAny>| -> PyResult<Result<f64, Vec<f64>>> {
        if let Ok(x) = v.extract::<f64>() {
            return Ok(Ok(x));
        }
        convert::sequence::<f64>(v, name).map(Err).map_err(|e| {
            if e.is_instance_of::<pyo3::exceptions::PyMemoryError>(v.py()) {
                e
            } else {
                pair_error()
            }
        })
    };
    Ok(match (side(&lo)?, side(&hi)?) {
        (Ok(lo), Ok(hi)) => Bounds::uniform(lo, hi),
        (Err(lo), Err(hi)) => Bounds::new(lo, hi),
        (Ok(lo), Err(hi)) => Bounds::new(vec![lo; hi.len()], hi),
        (Err(lo), Ok(hi)) => Bounds::new(lo.clone(), vec![hi; lo.len()]),
    })
}

/// The TL-CLF-CBF shield (paper Eq. 5D2): corrects an RL action so the FSA state's safe set
/// and the user's barriers stay positive, and nudges towards the task's next goal.
#[pyclass(name = "Shield", module = "tlshield._core", frozen)]
pub struct PyShield {
    pub(crate) inner: Shield,
    /// The user's model whose callables give `f`, `g` and `J_f` at every call, if any.
    pub(crate) custom: Option<Py<PyControlAffine>>,
    /// Names of the user barriers, then of every atom (positive, negated), made once.
    pub(crate) barrier_names: Vec<Py<PyString>>,
    pub(crate) literals: LiteralNames,
}

fn automaton_of(obj: &Bound<'_, PyAny>) -> PyResult<Arc<Automaton>> {
    if let Ok(spec) = obj.cast::<PySpec>() {
        return spec.get().shared_automaton(spec.py());
    }
    if let Ok(aut) = obj.cast::<PyAutomaton>() {
        return Ok(aut.get().inner.clone());
    }
    Err(PyTypeError::new_err(format!(
        "spec: expected a tlshield.Spec (or its Automaton), got {}",
        obj.get_type()
            .name()
            .map_or_else(|_| "?".into(), |n| n.to_string())
    )))
}

/// `{dimension: bound}` as the core's `(d, w_d)` pairs, in order of dimension; the bounds'
/// values are checked by the core.
fn disturbance_bounds(obj: &Bound<'_, PyAny>) -> PyResult<Vec<(usize, f64)>> {
    let dict = obj.cast::<PyDict>().map_err(|_| {
        PyTypeError::new_err(format!(
            "disturbance: expected a dict {{state dimension: bound}}, got {}",
            obj.get_type()
                .name()
                .map_or_else(|_| "?".into(), |n| n.to_string())
        ))
    })?;
    let mut out = Vec::with_capacity(dict.len());
    for (key, value) in dict.iter() {
        let d: i64 = key.extract().map_err(|_| {
            PyTypeError::new_err(format!(
                "disturbance: key {key}: expected a state dimension (int)"
            ))
        })?;
        let d = usize::try_from(d).map_err(|_| {
            PyValueError::new_err(format!("disturbance: key {d}: expected a dimension >= 0"))
        })?;
        let w: f64 = value.extract().map_err(|_| {
            PyTypeError::new_err(format!("disturbance[{d}]: expected a number, got {value}"))
        })?;
        out.push((d, w));
    }
    out.sort_by_key(|&(d, _)| d);
    Ok(out)
}

/// `give_way`: a sequence of names (a lone string is refused: it would read as its letters).
fn names(obj: &Bound<'_, PyAny>) -> PyResult<Vec<String>> {
    if obj.is_instance_of::<PyString>() {
        return Err(PyTypeError::new_err(
            "give_way: expected a sequence of barrier or atom names, got one string; write \
             [name]",
        ));
    }
    obj.try_iter()
        .map_err(|_| PyTypeError::new_err("give_way: expected a sequence of names (str)"))?
        .map(|item| {
            item?
                .extract::<String>()
                .map_err(|_| PyTypeError::new_err("give_way: expected a sequence of names (str)"))
        })
        .collect()
}

#[pymethods]
impl PyShield {
    #[new]
    #[pyo3(signature = (
        spec, dynamics, *, alpha, c3, k, cbf_bounds, clf_bounds, action_bounds=None,
        rl_bounds=None, barriers=None, pos=None, use_cbf=true, use_clf=true, solver="auto",
        slack_penalty=None, margin=None, alpha2=None, clf_gain=None, preserve_progress=true,
        inputs=None, disturbance=None, route=true, route_clearance=None, heading=None,
        speed=None, clf_round=None, dt=None, give_way=None,
    ))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        spec: &Bound<'_, PyAny>,
        dynamics: &Bound<'_, PyAny>,
        alpha: f64,
        c3: f64,
        k: f64,
        cbf_bounds: &Bound<'_, PyAny>,
        clf_bounds: &Bound<'_, PyAny>,
        action_bounds: Option<&Bound<'_, PyAny>>,
        rl_bounds: Option<&Bound<'_, PyAny>>,
        barriers: Option<&Bound<'_, PyAny>>,
        pos: Option<&Bound<'_, PyAny>>,
        use_cbf: bool,
        use_clf: bool,
        solver: &str,
        slack_penalty: Option<f64>,
        margin: Option<f64>,
        alpha2: Option<f64>,
        clf_gain: Option<f64>,
        preserve_progress: bool,
        inputs: Option<usize>,
        disturbance: Option<&Bound<'_, PyAny>>,
        route: bool,
        route_clearance: Option<f64>,
        heading: Option<usize>,
        speed: Option<usize>,
        clf_round: Option<(usize, usize, f64)>,
        dt: Option<f64>,
        give_way: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let automaton = automaton_of(spec)?;
        let custom = dynamics
            .cast::<PyControlAffine>()
            .ok()
            .map(|c| c.clone().unbind());
        let dynamics = match custom {
            Some(_) => None,
            None => model_of(dynamics)?,
        };
        let pos = match pos {
            Some(p) => crate::convert::indices(p, "pos")?,
            None => Vec::new(),
        };
        let params = ShieldParams::new(
            alpha,
            c3,
            k,
            bounds(cbf_bounds, "cbf_bounds")?,
            bounds(clf_bounds, "clf_bounds")?,
        )
        .with_action_bounds(
            action_bounds
                .map(|b| bounds(b, "action_bounds"))
                .transpose()?,
        )
        .with_rl_bounds(rl_bounds.map(|b| bounds(b, "rl_bounds")).transpose()?)
        .with_barriers(
            barriers
                .map(crate::barrier::barriers)
                .transpose()?
                .unwrap_or_default(),
        )
        .with_pos(pos)
        .with_parts(use_cbf, use_clf)
        .with_solver(map(SolverChoice::parse(solver))?)
        // None keeps the core's defaults (ShieldParams::DEFAULT_SLACK_PENALTY, DEFAULT_MARGIN).
        .with_slack_penalty(slack_penalty.unwrap_or(ShieldParams::DEFAULT_SLACK_PENALTY))
        .with_margin(margin.unwrap_or(ShieldParams::DEFAULT_MARGIN))
        .with_alpha2(alpha2)
        .with_dt(dt)
        .with_give_way(give_way.map(names).transpose()?.unwrap_or_default())
        .with_clf_gain(clf_gain.unwrap_or(ShieldParams::DEFAULT_CLF_GAIN))
        .with_preserve_progress(preserve_progress)
        .with_route(
            route,
            route_clearance.unwrap_or(tlshield_core::route::DEFAULT_CLEARANCE),
        )
        .with_heading(heading)
        .with_speed(speed)
        .with_inputs(inputs)
        .with_clf_round(
            clf_round.map(|(i, j, radius)| tlshield_core::shield::RoundBound {
                inputs: [i, j],
                radius,
            }),
        )
        .with_disturbance(
            disturbance
                .map(disturbance_bounds)
                .transpose()?
                .unwrap_or_default(),
        );
        let barrier_names = params
            .barriers
            .iter()
            .map(|b| PyString::new(py, &b.name).unbind())
            .collect();
        let literals = LiteralNames::new(py, automaton.spec().atoms());
        let inner = match &custom {
            Some(model) => Shield::with_custom_model(automaton, model.get().inner.clone(), params),
            None => Shield::new(automaton, dynamics, params),
        };
        Ok(PyShield {
            inner: map(inner)?,
            custom,
            barrier_names,
            literals,
        })
    }

    /// Number of inputs m.
    #[getter]
    fn num_inputs(&self) -> usize {
        self.inner.inputs()
    }

    /// Whether the CLF's target is routed around the discs the shield keeps the robot out of
    /// (``route=True``, the CLF on, a two-dimensional ``pos``).
    #[getter]
    fn routes(&self) -> bool {
        self.inner.routing().is_some()
    }

    /// The automaton whose safe sets and goals the shield uses.
    #[getter]
    fn automaton(&self, py: Python<'_>) -> PyAutomaton {
        PyAutomaton::new(py, self.inner.automaton().clone())
    }

    fn __repr__(&self) -> String {
        let c = self.inner.params();
        format!(
            "Shield(alpha={}, c3={}, k={}, use_cbf={}, use_clf={}, barriers={}, pos={:?}, inputs={})",
            c.alpha,
            c.c3,
            c.k,
            c.use_cbf,
            c.use_clf,
            c.barriers.len(),
            c.pos,
            self.inner.inputs()
        )
    }
}

//! `Shield` and its results, `FilterResult` and `FilterBatch`.

use std::sync::Arc;

use numpy::{IntoPyArray, PyArray1, PyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString, PyTuple};
use tlshield_core::{
    Automaton, Barrier, BarrierSource, BatchDynamics, BatchGradient, BatchOutput, Bounds,
    ControlAffine, Filtered, Shield, ShieldParams, SolvedBy, SolverChoice, Status,
};

use crate::automaton::PyAutomaton;
use crate::codes;
use crate::convert::{self, state, vector, FloatArray};
use crate::custom::PyControlAffine;
use crate::dynamics::model_of;
use crate::errors::map;
use crate::literals::LiteralNames;
use crate::monitor::{PyMonitor, PyMonitorBatch};
use crate::predicate::predicate_of;
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

/// Bounds from `(lo, hi)`, each a scalar (broadcast to m) or a length-m sequence.
fn bounds(obj: &Bound<'_, PyAny>, name: &str, m: usize) -> PyResult<Bounds> {
    let pair_error = || {
        PyTypeError::new_err(format!(
            "{name}: expected a pair (lo, hi) of numbers or of length-{m} sequences"
        ))
    };
    let [lo, hi] = pair(obj).ok_or_else(pair_error)?;
    let side = |v: &Bound<'_, PyAny>| -> PyResult<Vec<f64>> {
        if let Ok(x) = v.extract::<f64>() {
            return Ok(vec![x; m]);
        }
        convert::sequence::<f64>(v, name).map_err(|e| {
            if e.is_instance_of::<pyo3::exceptions::PyMemoryError>(v.py()) {
                e
            } else {
                pair_error()
            }
        })
    };
    Ok(Bounds {
        lo: side(&lo)?,
        hi: side(&hi)?,
    })
}

/// Barriers from a sequence of predicates (named `h0`, `h1`, ...) or a mapping name ->
/// predicate or `(predicate, slack weight)`; a name starting with `!` keeps the state out of
/// the predicate's region.
fn barriers(obj: &Bound<'_, PyAny>) -> PyResult<Vec<Barrier>> {
    if let Ok(items) = obj.call_method0("items") {
        let mut out = Vec::new();
        for item in items.try_iter()? {
            let (key, value): (Bound<'_, PyAny>, Bound<'_, PyAny>) = item?.extract()?;
            let name: String = key
                .extract()
                .map_err(|_| PyTypeError::new_err("barriers: mapping keys must be names (str)"))?;
            let (value, weight) = match value.extract::<(Bound<'_, PyAny>, f64)>() {
                Ok((p, w)) => (p, w),
                Err(_) => (value, 1.0),
            };
            let predicate = predicate_of(&format!("barriers[{name:?}]"), &value)?;
            out.push(Barrier::named(name, predicate).with_slack_weight(weight));
        }
        return Ok(out);
    }
    let mut out = Vec::new();
    let iter = obj.try_iter().map_err(|_| {
        PyTypeError::new_err(
            "barriers: expected a sequence of Halfspace/Ball or a mapping name -> predicate",
        )
    })?;
    for (i, item) in iter.enumerate() {
        let item = item?;
        out.push(Barrier::inside(
            Barrier::default_name(i),
            predicate_of(&format!("barriers[{i}]"), &item)?,
        ));
    }
    Ok(out)
}

/// The outcome of one ``Shield.filter`` call.
#[pyclass(name = "FilterResult", module = "tlshield._core", frozen)]
pub struct PyFilterResult {
    /// The action to apply, ``a_rl + a_cbf + a_clf`` (m,).
    #[pyo3(get)]
    action: Py<PyArray1<f64>>,
    /// The safety correction (m,); zeros when the CBF is off.
    #[pyo3(get)]
    a_cbf: Py<PyArray1<f64>>,
    /// The task correction (m,); zeros when the CLF is off or there is no goal.
    #[pyo3(get)]
    a_clf: Py<PyArray1<f64>>,
    /// The CLF relaxation (0 when the CLF condition holds).
    #[pyo3(get)]
    delta: f64,
    status: Status,
    /// The largest barrier slack (0 unless relaxed).
    #[pyo3(get)]
    slack: f64,
    /// The CLF goal point (len(pos),) or None.
    #[pyo3(get)]
    goal: Option<Py<PyArray1<f64>>>,
    solver: SolvedBy,
    /// The barriers enforced this step: ``(name, h(s))``; safe-set literals are named as in
    /// the formula (``"g3"``, ``"!g3"`` when negated), user barriers by their given name.
    #[pyo3(get)]
    barriers: Vec<(Py<PyString>, f64)>,
}

#[pymethods]
impl PyFilterResult {
    /// ``Status.SOLVED``, ``Status.RELAXED`` (barrier rows needed slack) or ``Status.FAILED``
    /// (zero corrections).
    #[getter]
    fn status<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        codes::status(py, self.status as u8)
    }

    /// Which solver answered: ``Solver.ACTIVE_SET``, ``Solver.CLARABEL`` or ``Solver.NONE``.
    #[getter]
    fn solver<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        codes::solver(py, self.solver as u8)
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        format!(
            "FilterResult(action={}, status={:?}, delta={}, solver={:?})",
            self.action.bind(py),
            self.status.name(),
            self.delta,
            self.solver.name()
        )
    }
}

/// The outcome of one ``Shield.filter_batch`` call: one row per state.
#[pyclass(name = "FilterBatch", module = "tlshield._core", frozen, get_all)]
pub struct PyFilterBatch {
    /// The actions to apply (B, m).
    action: Py<PyArray2<f64>>,
    /// The safety corrections (B, m).
    a_cbf: Py<PyArray2<f64>>,
    /// The task corrections (B, m).
    a_clf: Py<PyArray2<f64>>,
    /// The CLF relaxations (B,).
    delta: Py<PyArray1<f64>>,
    /// The largest barrier slack per row (B,).
    slack: Py<PyArray1<f64>>,
    /// ``tlshield.Status`` values (B,) uint8: ``batch.status == Status.RELAXED``.
    status: Py<PyArray1<u8>>,
    /// ``tlshield.Solver`` values (B,) uint8.
    solver: Py<PyArray1<u8>>,
}

#[pymethods]
impl PyFilterBatch {
    fn __len__(&self, py: Python<'_>) -> usize {
        self.delta.bind(py).len()
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        format!("FilterBatch(rows={})", self.delta.bind(py).len())
    }
}

/// The TL-CLF-CBF shield (paper Eq. 5D2): corrects an RL action so the FSA state's safe set
/// and the user's barriers stay positive, and nudges towards the task's next goal.
#[pyclass(name = "Shield", module = "tlshield._core", frozen)]
pub struct PyShield {
    inner: Shield,
    /// The user's model whose callables give `f`, `g` and `J_f` at every call, if any.
    custom: Option<Py<PyControlAffine>>,
    /// Names of the user barriers, then of every atom (positive, negated), made once.
    barrier_names: Vec<Py<PyString>>,
    literals: LiteralNames,
}

impl PyShield {
    /// The core shield.
    pub(crate) fn core(&self) -> &Shield {
        &self.inner
    }

    /// Runs `call` with the per-call dynamics ``f`` (n,) and ``g`` (n, m) when both are given,
    /// with the model's when neither is; a `ControlAffine` model is evaluated at `s`.
    fn with_dynamics<R>(
        &self,
        py: Python<'_>,
        s: &[f64],
        f: Option<&Bound<'_, PyAny>>,
        g: Option<&Bound<'_, PyAny>>,
        call: impl FnOnce(Option<ControlAffine<'_>>) -> PyResult<R>,
    ) -> PyResult<R> {
        if let Some(model) = &self.custom {
            if f.is_some() || g.is_some() {
                return Err(PyValueError::new_err(
                    "this shield's ControlAffine model gives f and g: do not pass them",
                ));
            }
            let model = model.get();
            let n = s.len();
            let m = self.inner.inputs();
            let (mut fv, mut gv, mut jac) = (vec![0.0; n], vec![0.0; n * m], vec![0.0; n * n]);
            model
                .fns
                .evaluate(py, s, &mut fv, &mut gv, Some(&mut jac))?;
            return call(Some(ControlAffine {
                f: &fv,
                g: &gv,
                jacobian: Some(&jac),
            }));
        }
        match (f, g) {
            (None, None) => call(None),
            (Some(f), Some(g)) => {
                let f = FloatArray::extract(f, "f", 1, "(n,)")?;
                let g = FloatArray::extract(g, "g", 2, "(n, m)")?;
                if g.shape()[1] != self.inner.inputs() {
                    return Err(PyValueError::new_err(format!(
                        "g: expected shape (n, {}), got ({}, {})",
                        self.inner.inputs(),
                        g.shape()[0],
                        g.shape()[1]
                    )));
                }
                call(Some(ControlAffine::new(f.values(), g.values())))
            }
            _ => Err(PyValueError::new_err(
                "pass both f and g (the control-affine dynamics at s), or neither",
            )),
        }
    }

    /// A `ControlAffine` model's `f`, `g` and `J_f` at every row of `states`; `None` for a
    /// shield whose dynamics the core evaluates.
    #[allow(clippy::type_complexity)]
    fn evaluate_rows(
        &self,
        py: Python<'_>,
        states: &[f64],
    ) -> PyResult<Option<(Vec<f64>, Vec<f64>, Vec<f64>)>> {
        self.custom
            .as_ref()
            .map(|model| model.get().evaluate_rows(py, states))
            .transpose()
    }

    /// A batch's columns as numpy arrays, ``(rows, m)`` matrices for the actions.
    fn batch_result(
        &self,
        py: Python<'_>,
        out: BatchOutput,
        rows: usize,
    ) -> PyResult<PyFilterBatch> {
        let m = self.inner.inputs();
        let matrix = |v: Vec<f64>| {
            numpy::ndarray::Array2::from_shape_vec((rows, m), v)
                .map(|a| a.into_pyarray(py).unbind())
                .map_err(|e| PyValueError::new_err(e.to_string()))
        };
        Ok(PyFilterBatch {
            action: matrix(out.action)?,
            a_cbf: matrix(out.a_cbf)?,
            a_clf: matrix(out.a_clf)?,
            delta: out.delta.into_pyarray(py).unbind(),
            slack: out.slack.into_pyarray(py).unbind(),
            status: out.status.into_pyarray(py).unbind(),
            solver: out.solver.into_pyarray(py).unbind(),
        })
    }

    pub(crate) fn result(&self, py: Python<'_>, out: Filtered) -> PyFilterResult {
        let barriers = out
            .barriers
            .iter()
            .map(|(source, h)| {
                let name = match source {
                    BarrierSource::User(i) => self.barrier_names[*i].clone_ref(py),
                    BarrierSource::SafeSet(literal) => self.literals.get(py, literal).unbind(),
                };
                (name, *h)
            })
            .collect();
        PyFilterResult {
            action: out.action.into_pyarray(py).unbind(),
            a_cbf: out.a_cbf.into_pyarray(py).unbind(),
            a_clf: out.a_clf.into_pyarray(py).unbind(),
            delta: out.delta,
            status: out.status,
            slack: out.slack,
            goal: out.goal.map(|g| g.into_pyarray(py).unbind()),
            solver: out.solver,
            barriers,
        }
    }
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

#[pymethods]
impl PyShield {
    #[new]
    #[pyo3(signature = (
        spec, dynamics, *, alpha, c3, k, cbf_bounds, clf_bounds, action_bounds=None,
        rl_bounds=None, barriers=None, pos=None, use_cbf=true, use_clf=true, solver="auto",
        slack_penalty=None, margin=None, alpha2=None, clf_gain=None, preserve_progress=true,
        inputs=None, disturbance=None, route=true, route_clearance=None, heading=None,
        clf_round=None,
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
        clf_round: Option<(usize, usize, f64)>,
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
        // m from the model, else from `inputs`, else from per-input CBF bounds; scalar bounds
        // alone do not say how many inputs there are.
        let from_model = match (&dynamics, &custom) {
            (Some(d), _) => Some(d.inputs()),
            (None, Some(c)) => Some(c.get().inner.inputs()),
            (None, None) => None,
        };
        let m = match (from_model, inputs) {
            (Some(m), Some(given)) if given != m => {
                return Err(PyValueError::new_err(format!(
                    "inputs={given}, but the model has {m} inputs"
                )))
            }
            (Some(m), _) => m,
            (None, Some(0)) => {
                return Err(PyValueError::new_err("inputs: expected at least 1, got 0"))
            }
            (None, Some(given)) => given,
            (None, None) => {
                let [lo, _] = pair(cbf_bounds)
                    .ok_or_else(|| PyTypeError::new_err("cbf_bounds: expected a pair (lo, hi)"))?;
                lo.len().map_err(|_| {
                    PyValueError::new_err(
                        "cbf_bounds: with dynamics=None the number of inputs is not known from \
                         scalar bounds; pass inputs=m, or per-input bounds ([lo_1, ..., lo_m], \
                         [hi_1, ..., hi_m])",
                    )
                })?
            }
        };
        let pos = match pos {
            Some(p) => crate::convert::indices(p, "pos")?,
            None => ShieldParams::DEFAULT_POS.to_vec(),
        };
        let params = ShieldParams::new(
            alpha,
            c3,
            k,
            bounds(cbf_bounds, "cbf_bounds", m)?,
            bounds(clf_bounds, "clf_bounds", m)?,
        )
        .with_action_bounds(
            action_bounds
                .map(|b| bounds(b, "action_bounds", m))
                .transpose()?,
        )
        .with_rl_bounds(rl_bounds.map(|b| bounds(b, "rl_bounds", m)).transpose()?)
        .with_barriers(
            barriers
                .map(self::barriers)
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
        .with_clf_gain(clf_gain.unwrap_or(ShieldParams::DEFAULT_CLF_GAIN))
        .with_preserve_progress(preserve_progress)
        .with_route(
            route,
            route_clearance.unwrap_or(tlshield_core::route::DEFAULT_CLEARANCE),
        )
        .with_heading(heading)
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

    /// One shield step: state ``s`` (n,), FSA state ``q`` (the state after reading ``s``),
    /// RL action ``a_rl`` (m,). ``f`` (n,) and ``g`` (n, m) override the dynamics model.
    /// ``drift`` (n,) is added to ``f``: the motion measured for this step of state dimensions
    /// the agent does not control (e.g. moving obstacles read by ``center_dims``). At a
    /// ``Monitor``'s state, use ``filter_monitor``.
    #[pyo3(signature = (s, q, a_rl, f=None, g=None, drift=None))]
    #[allow(clippy::too_many_arguments)]
    fn filter(
        &self,
        py: Python<'_>,
        s: &Bound<'_, PyAny>,
        q: &Bound<'_, PyAny>,
        a_rl: &Bound<'_, PyAny>,
        f: Option<&Bound<'_, PyAny>>,
        g: Option<&Bound<'_, PyAny>>,
        drift: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyFilterResult> {
        if s.cast::<PyMonitor>().is_ok() {
            return Err(PyTypeError::new_err(
                "filter(s, q, a_rl): s is a Monitor; use filter_monitor(monitor, a_rl)",
            ));
        }
        let drift = drift.map(|d| vector(d, "drift")).transpose()?;
        let drift = drift.as_deref();
        let s = vector(s, "s")?;
        let q = state(q, "q", self.inner.automaton())?;
        let a_rl = FloatArray::extract(a_rl, "a_rl", 1, "(m,)")?
            .values()
            .to_vec();
        let out = self.with_dynamics(py, &s, f, g, |fg| {
            map(self.inner.filter(&s, q, &a_rl, fg, drift))
        })?;
        Ok(self.result(py, out))
    }

    /// One shield step at a ``Monitor``'s last state and FSA state, reusing its reading of the
    /// atoms and its CLF goal (the per-step path: ``monitor.advance(s_next)``, then
    /// ``shield.filter_monitor(monitor, a_rl)``). ``a_rl`` (m,); ``f``, ``g`` and ``drift`` as
    /// in ``filter``.
    #[pyo3(signature = (monitor, a_rl, f=None, g=None, drift=None))]
    fn filter_monitor(
        &self,
        py: Python<'_>,
        monitor: &Bound<'_, PyMonitor>,
        a_rl: &Bound<'_, PyAny>,
        f: Option<&Bound<'_, PyAny>>,
        g: Option<&Bound<'_, PyAny>>,
        drift: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyFilterResult> {
        let drift = drift.map(|d| vector(d, "drift")).transpose()?;
        let drift = drift.as_deref();
        let a_rl = FloatArray::extract(a_rl, "a_rl", 1, "(m,)")?
            .values()
            .to_vec();
        let monitor = monitor.borrow();
        let s = monitor.inner.state();
        let out = self.with_dynamics(py, s, f, g, |fg| {
            map(self.inner.filter_monitor(&monitor.inner, &a_rl, fg, drift))
        })?;
        Ok(self.result(py, out))
    }

    /// Shields the rows of a ``MonitorBatch`` at their last states and FSA states, reusing each
    /// row's reading of the atoms and its goal: ``a_rl`` (B, m), ``drift`` (B, n) optional.
    /// Returns a ``FilterBatch`` (see ``filter_batch``).
    #[pyo3(signature = (monitors, a_rl, drift=None))]
    fn filter_monitors<'py>(
        &self,
        py: Python<'py>,
        monitors: &Bound<'py, PyMonitorBatch>,
        a_rl: &Bound<'py, PyAny>,
        drift: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<PyFilterBatch> {
        let monitors = monitors.borrow();
        let rows = monitors.inner.len();
        let a_rl = FloatArray::extract(a_rl, "a_rl", 2, "(B, m)")?;
        let drift = drift
            .map(|d| FloatArray::extract(d, "drift", 2, "(B, n)"))
            .transpose()?;
        let m = self.inner.inputs();
        if a_rl.shape() != [rows, m] {
            return Err(PyValueError::new_err(format!(
                "filter_monitors: expected a_rl ({rows}, {m}) for {rows} monitors, got {}",
                crate::convert::shape_text(a_rl.shape())
            )));
        }
        let (actions, drift_values) = (a_rl.values(), drift.as_ref().map(|d| d.values()));
        let shield = &self.inner;
        let mut out = BatchOutput::default();
        let batch = &monitors.inner;
        let states: Vec<f64> = match &self.custom {
            Some(_) => batch
                .monitors()
                .iter()
                .flat_map(|m| m.state())
                .copied()
                .collect(),
            None => Vec::new(),
        };
        let evaluated = self.evaluate_rows(py, &states)?;
        let dynamics = evaluated.as_ref().map(|(f, g, j)| BatchDynamics {
            f,
            g,
            jacobian: Some(j),
        });
        map(py.detach(|| {
            shield.filter_monitors_with(batch, actions, dynamics, drift_values, &mut out)
        }))?;
        self.batch_result(py, out, rows)
    }

    /// Shields a batch: ``states`` (B, n), ``qs`` (B,), ``a_rl`` (B, m), using the dynamics
    /// model. Parallel over rows with the GIL released. Returns a ``FilterBatch`` of arrays:
    /// ``action``, ``a_cbf``, ``a_clf`` (B, m), ``delta``, ``slack`` (B,), ``status`` (B,)
    /// ``tlshield.Status`` values and ``solver`` (B,) ``tlshield.Solver`` values (uint8).
    /// ``drift`` (B, n), optional, is added to each row's ``f`` (see ``filter``).
    /// At the rows of a ``MonitorBatch``, use ``filter_monitors``.
    #[pyo3(signature = (states, qs, a_rl, drift=None))]
    fn filter_batch<'py>(
        &self,
        py: Python<'py>,
        states: &Bound<'py, PyAny>,
        qs: &Bound<'py, PyAny>,
        a_rl: &Bound<'py, PyAny>,
        drift: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<PyFilterBatch> {
        if states.cast::<PyMonitorBatch>().is_ok() {
            return Err(PyTypeError::new_err(
                "filter_batch(states, qs, a_rl): states is a MonitorBatch; use \
                 filter_monitors(monitors, a_rl)",
            ));
        }
        let states = FloatArray::extract(states, "states", 2, "(B, n)")?;
        let drift = drift
            .map(|d| FloatArray::extract(d, "drift", 2, "(B, n)"))
            .transpose()?;
        if let Some(d) = &drift {
            if d.shape() != states.shape() {
                return Err(PyValueError::new_err(format!(
                    "filter_batch: drift must have the shape of states {}, got {}",
                    crate::convert::shape_text(states.shape()),
                    crate::convert::shape_text(d.shape())
                )));
            }
        }
        let drift_values = drift.as_ref().map(|d| d.values());
        let a_rl = FloatArray::extract(a_rl, "a_rl", 2, "(B, m)")?;
        let qs_usize = convert::states(qs, "qs", self.inner.automaton())?;
        let (rows, n, m) = (states.shape()[0], states.shape()[1], self.inner.inputs());
        if qs_usize.len() != rows || a_rl.shape() != [rows, m] {
            return Err(PyValueError::new_err(format!(
                "filter_batch: expected qs ({rows},) and a_rl ({rows}, {m}) for {rows} states, \
                 got qs ({},) and a_rl {}",
                qs_usize.len(),
                crate::convert::shape_text(a_rl.shape())
            )));
        }
        let (values, actions) = (states.values(), a_rl.values());
        let shield = &self.inner;
        let mut out = BatchOutput::default();
        let drift = drift_values;
        let evaluated = match &self.custom {
            Some(model) if n != model.get().inner.state_len() => {
                return Err(PyValueError::new_err(format!(
                    "states: expected rows of {} values (the model's state_dim), got {n}",
                    model.get().inner.state_len()
                )))
            }
            _ => self.evaluate_rows(py, values)?,
        };
        let dynamics = evaluated.as_ref().map(|(f, g, j)| BatchDynamics {
            f,
            g,
            jacobian: Some(j),
        });
        map(py.detach(|| {
            shield.filter_batch_with(values, n, &qs_usize, actions, dynamics, drift, &mut out)
        }))?;
        self.batch_result(py, out, rows)
    }

    /// Vector-Jacobian products of ``filter_batch(states, qs, a_rl)``: for ``grad_action``
    /// ``(B, m)``, the upstream gradient ``dL/daction``, returns ``(grad_a_rl, grad_states,
    /// flags)``: ``dL/da_rl`` ``(B, m)``, ``dL/dstates`` ``(B, n)`` (``None`` with
    /// ``state_grad=False``) and a ``uint8`` per row, an OR of ``tlshield.GradFlag`` bits:
    /// ``RELAXED`` (the relaxed QP was solved and differentiated), ``FAILED`` (the step returned
    /// ``a_rl``; identity gradient), ``DEGENERATE`` (the active set changes here: the
    /// one-sided derivative of the piece on which every tight row stays tight) and
    /// ``SINGULAR``. Each row is solved again as ``filter_batch`` solves it. Parallel over rows
    /// with the GIL released. State gradients need a built-in model and first-order rows
    /// (HOCBF rows raise ``ShieldError``).
    #[pyo3(signature = (states, qs, a_rl, grad_action, drift=None, state_grad=true))]
    #[allow(clippy::too_many_arguments)]
    fn vjp_batch<'py>(
        &self,
        py: Python<'py>,
        states: &Bound<'py, PyAny>,
        qs: &Bound<'py, PyAny>,
        a_rl: &Bound<'py, PyAny>,
        grad_action: &Bound<'py, PyAny>,
        drift: Option<&Bound<'py, PyAny>>,
        state_grad: bool,
    ) -> PyResult<GradientTuple> {
        let grad = FloatArray::extract(grad_action, "grad_action", 2, "(B, m)")?;
        let input = GradientInput::extract(self, py, "vjp_batch", states, qs, a_rl, drift)?;
        let (rows, n, m) = (input.rows, input.n, self.inner.inputs());
        if grad.shape() != [rows, m] {
            return Err(PyValueError::new_err(format!(
                "vjp_batch: expected grad_action ({rows}, {m}) for {rows} states, got {}",
                convert::shape_text(grad.shape())
            )));
        }
        let mut out = BatchGradient::default();
        let shield = &self.inner;
        let (grads, values, actions) = (grad.values(), input.states.values(), input.a_rl.values());
        let (dynamics, drift, qs) = (input.dynamics(), input.drift(), &input.qs);
        map(py.detach(|| {
            shield.vjp_batch(
                values, n, qs, actions, grads, dynamics, drift, state_grad, &mut out,
            )
        }))?;
        let (a_rl, states, flags) = gradient_arrays(py, out, rows, &[m], state_grad.then_some(n))?;
        Ok((a_rl, states, flags))
    }

    /// The shielded actions of ``filter_batch(states, qs, a_rl)`` and their Jacobians, in one
    /// pass (one QP solve and factorisation per row): returns ``(action, jac_a_rl, jac_states,
    /// flags)``, ``action`` ``(B, m)``, ``jac_a_rl`` ``(B, m, m)`` with ``[b, k, j] =
    /// d action_k / d a_rl_j``, ``jac_states`` ``(B, m, n)`` (``None`` with
    /// ``state_grad=False``) and the ``GradFlag`` bits per row (see ``vjp_batch``).
    /// ``tlshield.torch.ShieldLayer`` uses it: its backward pass is then a product.
    #[pyo3(signature = (states, qs, a_rl, drift=None, state_grad=true))]
    #[allow(clippy::too_many_arguments)]
    fn jacobian_batch<'py>(
        &self,
        py: Python<'py>,
        states: &Bound<'py, PyAny>,
        qs: &Bound<'py, PyAny>,
        a_rl: &Bound<'py, PyAny>,
        drift: Option<&Bound<'py, PyAny>>,
        state_grad: bool,
    ) -> PyResult<JacobianTuple> {
        let input = GradientInput::extract(self, py, "jacobian_batch", states, qs, a_rl, drift)?;
        let (rows, n, m) = (input.rows, input.n, self.inner.inputs());
        let mut out = BatchGradient::default();
        let shield = &self.inner;
        let (values, actions) = (input.states.values(), input.a_rl.values());
        let (dynamics, drift, qs) = (input.dynamics(), input.drift(), &input.qs);
        map(py.detach(|| {
            shield.jacobian_batch(
                values, n, qs, actions, dynamics, drift, state_grad, &mut out,
            )
        }))?;
        let action =
            numpy::ndarray::Array2::from_shape_vec((rows, m), std::mem::take(&mut out.action))
                .map(|a| a.into_pyarray(py).unbind())
                .map_err(|e| PyValueError::new_err(e.to_string()))?;
        let (jac_a, jac_s, flags) =
            gradient_arrays(py, out, rows, &[m, m], state_grad.then_some(n))?;
        Ok((action, jac_a, jac_s, flags))
    }

    /// Every user barrier's value ``h(s)`` by name (> 0 while it holds): how a step is
    /// measured when the environment reports no violation of its own.
    fn barrier_values<'py>(
        &self,
        py: Python<'py>,
        s: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let s = vector(s, "s")?;
        let mut values = Vec::new();
        map(self.inner.barrier_values(&s, &mut values))?;
        let out = PyDict::new(py);
        for (name, h) in self.barrier_names.iter().zip(values) {
            out.set_item(name.bind(py), h)?;
        }
        Ok(out)
    }

    /// Number of inputs m.
    #[getter]
    fn num_inputs(&self) -> usize {
        self.inner.inputs()
    }

    /// The automaton whose safe sets and goals the shield uses.
    #[getter]
    fn automaton(&self, py: Python<'_>) -> PyAutomaton {
        PyAutomaton::new(py, self.inner.automaton().clone())
    }

    /// Pickled as its constructor's arguments: the spec (its formula text and predicates),
    /// the model, and every parameter as numbers, lists and names; rebuilt on load.
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        let shield = &slf.get().inner;
        let p = shield.params();
        let spec = Bound::new(py, PySpec::from_core(shield.automaton().spec().clone()))?;
        let model = match (shield.dynamics(), &slf.get().custom) {
            (Some(d), _) => crate::dynamics::to_python(py, d)?,
            (None, Some(custom)) => custom.bind(py).clone().into_any(),
            (None, None) => py.None().into_bound(py),
        };
        let pair = |b: &Bounds| (b.lo.clone(), b.hi.clone());
        let barriers = PyDict::new(py);
        for b in &p.barriers {
            if !b.named_for_its_side() {
                return Err(PyValueError::new_err(format!(
                    "barrier {:?}: a name starting with '!' must mean 'outside' to be pickled",
                    b.name
                )));
            }
            let predicate = crate::predicate::to_python(py, &b.predicate)?;
            barriers.set_item(&b.name, (predicate, b.slack_weight))?;
        }
        let kwargs = PyDict::new(py);
        kwargs.set_item("alpha", p.alpha)?;
        kwargs.set_item("c3", p.c3)?;
        kwargs.set_item("k", p.k)?;
        kwargs.set_item("cbf_bounds", pair(&p.cbf_bounds))?;
        kwargs.set_item("clf_bounds", pair(&p.clf_bounds))?;
        kwargs.set_item("action_bounds", p.action_bounds.as_ref().map(pair))?;
        kwargs.set_item("rl_bounds", p.rl_bounds.as_ref().map(pair))?;
        kwargs.set_item("barriers", barriers)?;
        kwargs.set_item("pos", p.pos.clone())?;
        kwargs.set_item("use_cbf", p.use_cbf)?;
        kwargs.set_item("use_clf", p.use_clf)?;
        kwargs.set_item("solver", p.solver.name())?;
        kwargs.set_item("slack_penalty", p.slack_penalty)?;
        kwargs.set_item("margin", p.margin)?;
        kwargs.set_item("alpha2", p.alpha2)?;
        kwargs.set_item("clf_gain", p.clf_gain)?;
        kwargs.set_item("preserve_progress", p.preserve_progress)?;
        kwargs.set_item("inputs", shield.inputs())?;
        kwargs.set_item("route", p.route)?;
        kwargs.set_item("route_clearance", p.route_clearance)?;
        kwargs.set_item("heading", p.heading)?;
        kwargs.set_item(
            "clf_round",
            p.clf_round.map(|r| (r.inputs[0], r.inputs[1], r.radius)),
        )?;
        let bounds = PyDict::new(py);
        for &(d, w) in &p.disturbance {
            bounds.set_item(d, w)?;
        }
        kwargs.set_item("disturbance", bounds)?;
        let args = PyTuple::new(py, [spec.into_any(), model])?;
        crate::pickling::reduce(slf.get_type().into_any(), args, Some(kwargs), None)
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

/// What ``vjp_batch`` returns: ``(grad_a_rl, grad_states or None, flags)``.
type GradientTuple = (Py<PyAny>, Option<Py<PyAny>>, Py<PyArray1<u8>>);
/// What ``jacobian_batch`` returns: ``(action, jac_a_rl, jac_states or None, flags)``.
type JacobianTuple = (
    Py<PyArray2<f64>>,
    Py<PyAny>,
    Option<Py<PyAny>>,
    Py<PyArray1<u8>>,
);

/// The checked input of a gradient call: states, FSA states, RL actions, drift and (for a
/// user's model) each row's dynamics.
struct GradientInput<'py> {
    states: FloatArray<'py>,
    qs: Vec<usize>,
    a_rl: FloatArray<'py>,
    drift: Option<FloatArray<'py>>,
    evaluated: Option<(Vec<f64>, Vec<f64>, Vec<f64>)>,
    rows: usize,
    n: usize,
}

impl<'py> GradientInput<'py> {
    #[allow(clippy::too_many_arguments)]
    fn extract(
        shield: &PyShield,
        py: Python<'py>,
        call: &str,
        states: &Bound<'py, PyAny>,
        qs: &Bound<'py, PyAny>,
        a_rl: &Bound<'py, PyAny>,
        drift: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Self> {
        let states = FloatArray::extract(states, "states", 2, "(B, n)")?;
        let a_rl = FloatArray::extract(a_rl, "a_rl", 2, "(B, m)")?;
        let drift = drift
            .map(|d| FloatArray::extract(d, "drift", 2, "(B, n)"))
            .transpose()?;
        let qs = convert::states(qs, "qs", shield.inner.automaton())?;
        let (rows, n, m) = (states.shape()[0], states.shape()[1], shield.inner.inputs());
        let shapes = [
            ("qs", vec![qs.len()], vec![rows]),
            ("a_rl", a_rl.shape().to_vec(), vec![rows, m]),
        ];
        let drift_shape = drift
            .as_ref()
            .map(|d| ("drift", d.shape().to_vec(), vec![rows, n]));
        for (what, got, want) in shapes.into_iter().chain(drift_shape) {
            if got != want {
                return Err(PyValueError::new_err(format!(
                    "{call}: expected {what} {} for {rows} states, got {}",
                    convert::shape_text(&want),
                    convert::shape_text(&got)
                )));
            }
        }
        let evaluated = shield.evaluate_rows(py, states.values())?;
        Ok(GradientInput {
            states,
            qs,
            a_rl,
            drift,
            evaluated,
            rows,
            n,
        })
    }

    fn dynamics(&self) -> Option<BatchDynamics<'_>> {
        self.evaluated.as_ref().map(|(f, g, j)| BatchDynamics {
            f,
            g,
            jacobian: Some(j),
        })
    }

    fn drift(&self) -> Option<&[f64]> {
        self.drift.as_ref().map(|d| d.values())
    }
}

/// The gradient's arrays as numpy: `a_rl` as `(rows, *shape)`, `states` as `(rows, *shape[..-1],
/// n)` when `n` is given, flags `(rows,)`.
fn gradient_arrays(
    py: Python<'_>,
    out: BatchGradient,
    rows: usize,
    shape: &[usize],
    n: Option<usize>,
) -> PyResult<GradientTuple> {
    let array = |v: Vec<f64>, tail: &[usize]| -> PyResult<Py<PyAny>> {
        let dims: Vec<usize> = std::iter::once(rows).chain(tail.iter().copied()).collect();
        numpy::ndarray::ArrayD::from_shape_vec(dims, v)
            .map(|a| a.into_pyarray(py).into_any().unbind())
            .map_err(|e| PyValueError::new_err(e.to_string()))
    };
    let lead = &shape[..shape.len() - 1];
    let states = n
        .map(|n| {
            let tail: Vec<usize> = lead.iter().copied().chain([n]).collect();
            array(out.states, &tail)
        })
        .transpose()?;
    Ok((
        array(out.a_rl, shape)?,
        states,
        out.flags.into_pyarray(py).unbind(),
    ))
}

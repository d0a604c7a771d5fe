//! `Shield`'s filtering calls: one step (`filter`, `filter_monitor`), a batch (`filter_batch`,
//! `filter_monitors`), and the barriers' values.

use numpy::IntoPyArray;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString};
use tlshield_core::{BarrierSource, BatchDynamics, BatchOutput, ControlAffine, Filtered, Shield};

use crate::convert::{state, vector, FloatArray};
use crate::errors::map;
use crate::monitor::{PyMonitor, PyMonitorBatch};
use crate::shield::{PyFilterBatch, PyFilterResult, PyShield};
use crate::shield_batch::BatchInput;

/// One step's converted `(s, q, a_rl, drift)`.
type OneCall = (Vec<f64>, usize, Vec<f64>, Option<Vec<f64>>);

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
        let f = f
            .map(|f| FloatArray::extract(f, "f", 1, "(n,)"))
            .transpose()?;
        let g = g
            .map(|g| FloatArray::extract(g, "g", 2, "(n, m)"))
            .transpose()?;
        if let Some(g) = g.as_ref().filter(|g| g.shape()[1] != self.inner.inputs()) {
            return Err(PyValueError::new_err(format!(
                "g: expected shape (n, {}), got ({}, {})",
                self.inner.inputs(),
                g.shape()[0],
                g.shape()[1]
            )));
        }
        let fg = map(ControlAffine::given(
            f.as_ref().map(FloatArray::values),
            g.as_ref().map(FloatArray::values),
        ))?;
        call(fg)
    }

    /// A `ControlAffine` model's `f`, `g` and `J_f` at every row of `states`; `None` for a
    /// shield whose dynamics the core evaluates.
    #[allow(clippy::type_complexity)]
    pub(crate) fn evaluate_rows(
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
            gave_way: self.gave_way_list(py, out.gave_way.into_iter())?,
            solver: out.solver.into_pyarray(py).unbind(),
        })
    }

    /// One step's `(s, q, a_rl, drift)`, converted and checked as `filter` and `problem` read
    /// them (a `q` the automaton lacks is a `ShieldError`).
    fn one_call(
        &self,
        py: Python<'_>,
        s: &Bound<'_, PyAny>,
        q: &Bound<'_, PyAny>,
        a_rl: &Bound<'_, PyAny>,
        drift: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<OneCall> {
        let drift = drift.map(|d| vector(d, "drift")).transpose()?;
        let s = vector(s, "s")?;
        let q = state(q, "q", self.inner.automaton())
            .map_err(|e| crate::errors::shield_state(py, e))?;
        let a_rl = FloatArray::extract(a_rl, "a_rl", 1, "(m,)")?
            .values()
            .to_vec();
        Ok((s, q, a_rl, drift))
    }

    /// The name of a barrier the shield enforced: the user's key, or the safe-set literal.
    pub(crate) fn source_name(&self, py: Python<'_>, source: &BarrierSource) -> Py<PyString> {
        match source {
            BarrierSource::User(i) => self.barrier_names[*i].clone_ref(py),
            BarrierSource::SafeSet(literal) => self.literals.get(py, literal).unbind(),
        }
    }

    /// Per row, `(name, slack)` of the barrier that gave way, or None.
    pub(crate) fn gave_way_list<'py>(
        &self,
        py: Python<'py>,
        rows: impl Iterator<Item = Option<(BarrierSource, f64)>>,
    ) -> PyResult<Py<PyList>> {
        let items = rows.map(|g| g.map(|(s, sigma)| (self.source_name(py, &s), sigma)));
        Ok(PyList::new(py, items)?.unbind())
    }

    pub(crate) fn result(&self, py: Python<'_>, out: Filtered) -> PyFilterResult {
        let name = |source: &BarrierSource| self.source_name(py, source);
        let barriers = out.barriers.iter().map(|(s, h)| (name(s), *h)).collect();
        let gave_way = out.gave_way.as_ref().map(|(s, sigma)| (name(s), *sigma));
        PyFilterResult {
            action: out.action.into_pyarray(py).unbind(),
            a_cbf: out.a_cbf.into_pyarray(py).unbind(),
            a_clf: out.a_clf.into_pyarray(py).unbind(),
            delta: out.delta,
            status: out.status,
            slack: out.slack,
            gave_way,
            goal: out.goal.map(|g| g.into_pyarray(py).unbind()),
            goal_unreachable: out.goal_unreachable,
            solver: out.solver,
            barriers,
        }
    }
}

#[pymethods]
impl PyShield {
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
        crate::errors::shield_call(py, || {
            if s.cast::<PyMonitor>().is_ok() {
                return Err(PyTypeError::new_err(
                    "filter(s, q, a_rl): s is a Monitor; use filter_monitor(monitor, a_rl)",
                ));
            }
            let (s, q, a_rl, drift) = self.one_call(py, s, q, a_rl, drift)?;
            let out = self.with_dynamics(py, &s, f, g, |fg| {
                map(self.inner.filter(&s, q, &a_rl, fg, drift.as_deref()))
            })?;
            Ok(self.result(py, out))
        })
    }

    /// The QP ``filter`` would solve at this step, before any relaxation: a dict of numpy
    /// arrays ``P_diag`` (the diagonal of P), ``c``, ``G`` (rows, vars) and ``h``, for
    /// ``min x'Px/2 + c'x  s.t.  G x <= h`` over ``x = [a_cbf | a_clf | d]`` (parts that are
    /// off are absent; ``d = delta - delta_0``); empty arrays when nothing is corrected. For
    /// inspecting a step and solving it independently. Arguments as in ``filter``.
    #[pyo3(signature = (s, q, a_rl, f=None, g=None, drift=None))]
    #[allow(clippy::too_many_arguments)]
    fn problem<'py>(
        &self,
        py: Python<'py>,
        s: &Bound<'py, PyAny>,
        q: &Bound<'py, PyAny>,
        a_rl: &Bound<'py, PyAny>,
        f: Option<&Bound<'py, PyAny>>,
        g: Option<&Bound<'py, PyAny>>,
        drift: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let qp = crate::errors::shield_call(py, || {
            let (s, q, a_rl, drift) = self.one_call(py, s, q, a_rl, drift)?;
            self.with_dynamics(py, &s, f, g, |fg| {
                map(self.inner.problem(&s, q, &a_rl, fg, drift.as_deref()))
            })
        })?;
        let vars = qp.p_diag.len();
        let rows = qp.h.len();
        let out = PyDict::new(py);
        out.set_item("P_diag", qp.p_diag.into_pyarray(py))?;
        out.set_item("c", qp.c.into_pyarray(py))?;
        let g = numpy::ndarray::Array2::from_shape_vec((rows, vars), qp.g)
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        out.set_item("G", g.into_pyarray(py))?;
        out.set_item("h", qp.h.into_pyarray(py))?;
        Ok(out)
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
        crate::errors::shield_call(py, || {
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
        })
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
        crate::errors::shield_call(py, || {
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
        })
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
        crate::errors::shield_call(py, || {
            if states.cast::<PyMonitorBatch>().is_ok() {
                return Err(PyTypeError::new_err(
                    "filter_batch(states, qs, a_rl): states is a MonitorBatch; use \
                 filter_monitors(monitors, a_rl)",
                ));
            }
            let input = BatchInput::extract(self, py, "filter_batch", [states, qs, a_rl], drift)?;
            let rows = input.rows().len();
            let shield = &self.inner;
            let mut out = BatchOutput::default();
            let (batch, a_rl, dynamics, drift) = input.parts();
            map(py.detach(|| shield.filter_batch_with(batch, a_rl, dynamics, drift, &mut out)))?;
            self.batch_result(py, out, rows)
        })
    }

    /// Every user barrier's value ``h(s)`` by name (> 0 while it holds): how a step is
    /// measured when the environment reports no violation of its own.
    fn barrier_values<'py>(
        &self,
        py: Python<'py>,
        s: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        crate::errors::shield_call(py, || {
            let s = vector(s, "s")?;
            let mut values = Vec::new();
            map(self.inner.barrier_values(&s, &mut values))?;
            let out = PyDict::new(py);
            for (name, h) in self.barrier_names.iter().zip(values) {
                out.set_item(name.bind(py), h)?;
            }
            Ok(out)
        })
    }
}

//! What the shield's filtering calls give: `FilterResult` (one step) and `FilterBatch` (one
//! row per state).

use numpy::{PyArray1, PyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyList, PyString};
use tlshield_core::{SolvedBy, Status};

use crate::codes;

/// The outcome of one ``Shield.filter`` call.
#[pyclass(name = "FilterResult", module = "tlshield._core", frozen)]
pub struct PyFilterResult {
    /// The action to apply, ``a_rl + a_cbf + a_clf`` (m,).
    #[pyo3(get)]
    pub(crate) action: Py<PyArray1<f64>>,
    /// The safety correction (m,); zeros when the CBF is off.
    #[pyo3(get)]
    pub(crate) a_cbf: Py<PyArray1<f64>>,
    /// The task correction (m,); zeros when the CLF is off or there is no goal.
    #[pyo3(get)]
    pub(crate) a_clf: Py<PyArray1<f64>>,
    /// The CLF relaxation (0 when the CLF condition holds).
    #[pyo3(get)]
    pub(crate) delta: f64,
    pub(crate) status: Status,
    /// The largest barrier slack (0 unless relaxed).
    #[pyo3(get)]
    pub(crate) slack: f64,
    /// When the QP was relaxed: ``(name, slack)`` of the barrier whose row gave way the most
    /// (named as in ``barriers``), else None.
    #[pyo3(get)]
    pub(crate) gave_way: Option<(Py<PyString>, f64)>,
    /// The CLF goal point (len(pos),) or None.
    #[pyo3(get)]
    pub(crate) goal: Option<Py<PyArray1<f64>>>,
    /// Whether this step's goal cannot be reached from the state, as far as the routing
    /// guidance can tell: it lies where the shield does not let the robot be (inside an
    /// avoided disc, outside a region the robot is kept in), or no way around the avoided
    /// discs leads to it. The shield then parks the robot safely short of it. False without a
    /// routed goal.
    #[pyo3(get)]
    pub(crate) goal_unreachable: bool,
    pub(crate) solver: SolvedBy,
    /// The barriers enforced this step: ``(name, h(s))``; safe-set literals are named as in
    /// the formula (``"g3"``, ``"!g3"`` when negated), user barriers by their given name.
    #[pyo3(get)]
    pub(crate) barriers: Vec<(Py<PyString>, f64)>,
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
    pub(crate) action: Py<PyArray2<f64>>,
    /// The safety corrections (B, m).
    pub(crate) a_cbf: Py<PyArray2<f64>>,
    /// The task corrections (B, m).
    pub(crate) a_clf: Py<PyArray2<f64>>,
    /// The CLF relaxations (B,).
    pub(crate) delta: Py<PyArray1<f64>>,
    /// The largest barrier slack per row (B,).
    pub(crate) slack: Py<PyArray1<f64>>,
    /// ``tlshield.Status`` values (B,) uint8: ``batch.status == Status.RELAXED``.
    pub(crate) status: Py<PyArray1<u8>>,
    /// ``tlshield.Solver`` values (B,) uint8.
    pub(crate) solver: Py<PyArray1<u8>>,
    /// Per row, ``(name, slack)`` of the barrier that gave way (see
    /// ``FilterResult.gave_way``), or None.
    pub(crate) gave_way: Py<PyList>,
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

//! `Shield` pickled as its constructor's arguments.

use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use tlshield_core::Bounds;

use crate::shield::PyShield;
use crate::spec::PySpec;

#[pymethods]
impl PyShield {
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
            let side = crate::barrier::to_side(py, b)?;
            barriers.set_item(&b.name, (side, b.slack_weight))?;
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
        kwargs.set_item("dt", p.dt)?;
        kwargs.set_item("give_way", p.give_way.clone())?;
        kwargs.set_item("clf_gain", p.clf_gain)?;
        kwargs.set_item("preserve_progress", p.preserve_progress)?;
        kwargs.set_item("inputs", shield.inputs())?;
        kwargs.set_item("route", p.route)?;
        kwargs.set_item("route_clearance", p.route_clearance)?;
        kwargs.set_item("heading", p.heading)?;
        kwargs.set_item("speed", p.speed)?;
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
}

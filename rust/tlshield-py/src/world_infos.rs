//! Every row's ``info`` dict of a `WorldsStep` as the single env's ``step`` builds it, in one
//! call: the same loop in Python was a large share of a vector env's step.

use numpy::{PyArrayMethods, PyUntypedArrayMethods};
use pyo3::intern;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString};

use crate::world::PyWorldsStep;

#[pymethods]
impl PyWorldsStep {
    /// Each row's ``info`` as the single env's ``step`` gives it, but the CLF goal and the
    /// barrier list (None and empty: a batch does not return them): ``constraints`` names the
    /// two constraints, ``shield`` says whether rows carry ``info["shield"]``, and
    /// ``status_of`` / ``solver_of`` map the status and solver codes to their enum members
    /// (a code they lack gives None).
    #[pyo3(signature = (constraints, shield, status_of, solver_of))]
    fn infos<'py>(
        &self,
        py: Python<'py>,
        constraints: (Bound<'py, PyString>, Bound<'py, PyString>),
        shield: bool,
        status_of: &Bound<'py, PyDict>,
        solver_of: &Bound<'py, PyDict>,
    ) -> PyResult<Bound<'py, PyList>> {
        let q = self.q.bind(py).readonly();
        let accepted = self.accepted.bind(py).readonly();
        let trapped = self.trapped.bind(py).readonly();
        let tl_reward = self.tl_reward.bind(py).readonly();
        let h = self.constraints.bind(py).readonly();
        let distance = self.min_obstacle_distance.bind(py).readonly();
        let collision = self.collision.bind(py).readonly();
        let violation = self.violation.bind(py).readonly();
        let delta = self.delta.bind(py).readonly();
        let status = self.status.bind(py).readonly();
        let slack = self.slack.bind(py).readonly();
        let solver = self.solver.bind(py).readonly();
        let (q, accepted, trapped) = (q.as_slice()?, accepted.as_slice()?, trapped.as_slice()?);
        let (tl_reward, h, distance) = (tl_reward.as_slice()?, h.as_slice()?, distance.as_slice()?);
        let (collision, violation) = (collision.as_slice()?, violation.as_slice()?);
        let (delta, status, slack) = (delta.as_slice()?, status.as_slice()?, slack.as_slice()?);
        let solver = solver.as_slice()?;
        let gave_way = self.gave_way.bind(py);
        let rows = q.len();
        // The action rows as numpy views, by iterating the (N, 2) arrays (numpy's own row
        // iteration: several times cheaper than indexing row by row).
        let mut views = [&self.action, &self.a_rl, &self.a_cbf, &self.a_clf]
            .map(|a| a.bind(py).clone())
            .map(|a| (a.shape()[0] == rows).then(|| a.into_any().try_iter()));
        let [Some(Ok(action)), Some(Ok(a_rl)), Some(Ok(a_cbf)), Some(Ok(a_clf))] = &mut views
        else {
            return Err(pyo3::exceptions::PyValueError::new_err(
                "WorldsStep: ragged rows",
            ));
        };
        let next = |it: &mut Bound<'py, pyo3::types::PyIterator>| -> PyResult<Bound<'py, PyAny>> {
            it.next().unwrap_or_else(|| {
                Err(pyo3::exceptions::PyValueError::new_err(
                    "WorldsStep: ragged rows",
                ))
            })
        };
        let infos = PyList::empty(py);
        for i in 0..rows {
            let info = PyDict::new(py);
            info.set_item(intern!(py, "fsa_state"), q[i])?;
            info.set_item(intern!(py, "action"), next(action)?)?;
            info.set_item(intern!(py, "success"), accepted[i])?;
            info.set_item(intern!(py, "trap"), trapped[i])?;
            info.set_item(intern!(py, "tl_reward"), tl_reward[i])?;
            let c = PyDict::new(py);
            c.set_item(&constraints.0, h[2 * i])?;
            c.set_item(&constraints.1, h[2 * i + 1])?;
            info.set_item(intern!(py, "constraints"), c)?;
            info.set_item(intern!(py, "min_obstacle_distance"), distance[i])?;
            info.set_item(intern!(py, "collision"), collision[i])?;
            info.set_item(intern!(py, "violation"), violation[i])?;
            if shield {
                let s = PyDict::new(py);
                s.set_item(intern!(py, "a_rl"), next(a_rl)?)?;
                s.set_item(intern!(py, "a_cbf"), next(a_cbf)?)?;
                s.set_item(intern!(py, "a_clf"), next(a_clf)?)?;
                s.set_item(intern!(py, "delta"), delta[i])?;
                s.set_item(intern!(py, "status"), status_of.get_item(status[i])?)?;
                s.set_item(intern!(py, "slack"), slack[i])?;
                s.set_item(intern!(py, "gave_way"), gave_way.get_item(i)?)?;
                s.set_item(intern!(py, "solver"), solver_of.get_item(solver[i])?)?;
                s.set_item(intern!(py, "goal"), py.None())?;
                s.set_item(intern!(py, "barriers"), PyDict::new(py))?;
                info.set_item(intern!(py, "shield"), s)?;
            }
            infos.append(info)?;
        }
        Ok(infos)
    }
}

//! The arrays of a batch call over states (`filter_batch`, `vjp_batch`, `jacobian_batch`):
//! converted once, their layouts matched to the states', their values checked by the core
//! before a user's model is evaluated at any row.

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use tlshield_core::{BatchDynamics, StateBatch};

use crate::convert::{self, shape_text, FloatArray};
use crate::errors::map;
use crate::shield::PyShield;

/// `states` (B, n), `qs` (B,), `a_rl` (B, m), `drift` (B, n) and, for a `ControlAffine`
/// shield, each row's `f`, `g` and `J_f`.
pub(crate) struct BatchInput<'py> {
    states: FloatArray<'py>,
    qs: Vec<usize>,
    a_rl: FloatArray<'py>,
    drift: Option<FloatArray<'py>>,
    evaluated: Option<(Vec<f64>, Vec<f64>, Vec<f64>)>,
}

impl<'py> BatchInput<'py> {
    /// Converts the call's arrays; `call` names it in a layout error (a 2-D array whose rows
    /// are not the states' rows, which a flat length cannot tell).
    pub(crate) fn extract(
        shield: &PyShield,
        py: Python<'py>,
        call: &str,
        [states, qs, a_rl]: [&Bound<'py, PyAny>; 3],
        drift: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Self> {
        let states = FloatArray::extract(states, "states", 2, "(B, n)")?;
        let a_rl = FloatArray::extract(a_rl, "a_rl", 2, "(B, m)")?;
        let drift = drift
            .map(|d| FloatArray::extract(d, "drift", 2, "(B, n)"))
            .transpose()?;
        let qs = convert::states(qs, "qs", shield.core().automaton())?;
        let (rows, m) = (states.shape()[0], shield.core().inputs());
        let layouts = [("a_rl", a_rl.shape(), [rows, m])].into_iter().chain(
            drift
                .as_ref()
                .map(|d| ("drift", d.shape(), [rows, states.shape()[1]])),
        );
        for (what, got, want) in layouts {
            if got != want {
                return Err(PyValueError::new_err(format!(
                    "{call}: expected {what} {} for {rows} states, got {}",
                    shape_text(&want),
                    shape_text(got)
                )));
            }
        }
        let mut input = BatchInput {
            states,
            qs,
            a_rl,
            drift,
            evaluated: None,
        };
        let (rows, a_rl, _, drift) = input.parts();
        map(shield.core().check_rows(rows, a_rl, drift))?;
        input.evaluated = shield.evaluate_rows(py, input.states.values())?;
        Ok(input)
    }

    /// The rows as the core reads them.
    pub(crate) fn rows(&self) -> StateBatch<'_> {
        StateBatch::new(self.states.values(), self.states.shape()[1], &self.qs)
    }

    /// What the core's batch call takes: the rows, the RL actions and the drift (row-major)
    /// and, from a `ControlAffine` model, each row's dynamics. Only these slices cross into a
    /// GIL-free closure; the arrays' handles stay with `self`.
    #[allow(clippy::type_complexity)]
    pub(crate) fn parts(
        &self,
    ) -> (
        StateBatch<'_>,
        &[f64],
        Option<BatchDynamics<'_>>,
        Option<&[f64]>,
    ) {
        let dynamics = self.evaluated.as_ref().map(|(f, g, j)| BatchDynamics {
            f,
            g,
            jacobian: Some(j),
        });
        let drift = self.drift.as_ref().map(|d| d.values());
        (self.rows(), self.a_rl.values(), dynamics, drift)
    }
}

//! `Shield`'s gradients: `vjp_batch` and `jacobian_batch` (their arrays converted by
//! `shield_batch::BatchInput`).

use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use tlshield_core::BatchGradient;

use crate::convert::{self, FloatArray};
use crate::errors::map;
use crate::shield::PyShield;
use crate::shield_batch::BatchInput;

#[pymethods]
impl PyShield {
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
        crate::errors::shield_call(py, || {
            let grad = FloatArray::extract(grad_action, "grad_action", 2, "(B, m)")?;
            let input = BatchInput::extract(self, py, "vjp_batch", [states, qs, a_rl], drift)?;
            let (rows, n, m) = (input.rows().len(), input.rows().n, self.inner.inputs());
            if grad.shape() != [rows, m] {
                return Err(PyValueError::new_err(format!(
                    "vjp_batch: expected grad_action ({rows}, {m}) for {rows} states, got {}",
                    convert::shape_text(grad.shape())
                )));
            }
            let mut out = BatchGradient::default();
            let shield = &self.inner;
            let (batch, a_rl, dynamics, drift) = input.parts();
            let grads = grad.values();
            map(py.detach(|| {
                shield.vjp_batch(batch, a_rl, grads, dynamics, drift, state_grad, &mut out)
            }))?;
            let (a_rl, states, flags) =
                gradient_arrays(py, out, rows, &[m], state_grad.then_some(n))?;
            Ok((a_rl, states, flags))
        })
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
        crate::errors::shield_call(py, || {
            let input = BatchInput::extract(self, py, "jacobian_batch", [states, qs, a_rl], drift)?;
            let (rows, n, m) = (input.rows().len(), input.rows().n, self.inner.inputs());
            let mut out = BatchGradient::default();
            let shield = &self.inner;
            let (batch, a_rl, dynamics, drift) = input.parts();
            map(py.detach(|| {
                shield.jacobian_batch(batch, a_rl, dynamics, drift, state_grad, &mut out)
            }))?;
            let action =
                numpy::ndarray::Array2::from_shape_vec((rows, m), std::mem::take(&mut out.action))
                    .map(|a| a.into_pyarray(py).unbind())
                    .map_err(|e| PyValueError::new_err(e.to_string()))?;
            let (jac_a, jac_s, flags) =
                gradient_arrays(py, out, rows, &[m, m], state_grad.then_some(n))?;
            Ok((action, jac_a, jac_s, flags))
        })
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

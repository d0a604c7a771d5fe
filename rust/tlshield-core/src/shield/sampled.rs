//! Barrier rows that hold the sampled states, when the plant holds the action for `dt` and
//! is sampled after an explicit Euler step of the model, `s' = s + dt (f(s) + g(s) a)`
//! ([`ShieldParams::dt`]). The continuous-time rows (`program.rs`) hold `dh/dt >= -alpha h`
//! at the sample only; between samples the state moves on a straight line, and on a double
//! integrator braking at a disc's rim it ends each step about 1e-4 m inside.
//!
//! Write `~h = h - margin`, `g1 = alpha dt` and `g2 = alpha2 dt` (both <= 1, checked at
//! construction).
//! - **First order** (discrete-time CBF, Agrawal & Sreenath): `~h(s') >= (1 - g1) ~h(s)`. With
//!   `y = s + dt f(s)` the successor of `a = 0`, `s'(a) = y + dt g a`, and the row is that
//!   condition linearised in `a` at 0, divided by `dt`:
//!   `L = grad ~h(y) . g(s)`, `r = (~h(y) - ~h(s)) / dt + alpha ~h(s)` (written so that where
//!   the step moves nothing `h` reads, `y` reads as `s`, the row is the continuous-time one
//!   bit for bit).
//! - **Second order** (discrete-time HOCBF, Xiong et al.): `psi(s) = (~h(y(s)) - ~h(s)) / dt +
//!   alpha ~h(s) >= 0` says the next sample keeps `~h >= (1 - g1) ~h`; the row keeps
//!   `psi(s') >= (1 - g2) psi(s)`. No input moves what `h` reads, so `~h(s')` is `~h(y)` whatever
//!   `a` is, and `psi(s')` reads the sample after next, `z(a) = s' + dt f(s')`, with
//!   `dz/da = dt (I + dt J_f(y)) g(s)` at `a = 0`. Divided by `dt`:
//!   `L = grad ~h(z0)^T (I + dt J_f(y)) g(s) / dt` and
//!   `r = (psi_next - psi(s)) / dt + alpha2 psi(s)` with `psi_next = (~h(z0) - ~h(y)) / dt +
//!   alpha ~h(y)` (`psi(s')` at `a = 0`), `z0 = y + dt f(y)`.
//!
//! Both tend to the continuous-time rows as `dt -> 0`. Exactness: where `~h` is convex along
//! the step and the successor is affine in `a` (the outside of a disc or any half-space, under
//! the single and double integrators, the unicycle's reference point and ThrustTurn), the
//! linearisation is a lower bound, so a solved row keeps the sampled state out by any amount.
//! Under the acceleration unicycle and the bicycle the next heading bends the step
//! ([`Dynamics::bends_step`]): `z(a)` is not affine in `a`, and a row linearised at `a = 0`
//! errs by `O(dt^3 |a|^2)` in `~h(z)` at the action taken. Under steady hard turning at a
//! disc's rim those errors added up to a millimetre inside it. So after the QP is solved, these
//! rows are linearised again at the action found (`y0 = s + dt (f(s) + g(s) a0)`, `z0 = y0 +
//! dt f(y0)`, `L = grad ~h(z0)^T (I + dt J_f(y0)) g(s) / dt`, `r` read at `z0`, the row
//! `r + L . (a - a0) >= 0`) and the QP solved again, until the action settles
//! (`Shield::step`): the rows then hold the sampled state of the action taken, to rounding.
//! Elsewhere (the inside of a disc) the error is second order in `dt a`.

use super::ShieldParams;
use crate::dynamics::Dynamics;
use crate::predicate::Predicate;

/// The predicted samples and gradients of one barrier's sampled row, reused from step to step.
#[derive(Debug, Default)]
pub(super) struct Sampled {
    /// `y = s + dt f(s)` and, for second-order rows, `z0 = y0 + dt f(y0)`, where `y0` is `y`,
    /// or, under a model that bends the step (`bent`), the step of the action the rows are
    /// linearised at.
    y: Vec<f64>,
    y0: Vec<f64>,
    z: Vec<f64>,
    /// Whether the model bends the step (see the module docs).
    pub(super) bent: bool,
    /// `f(y)` and `g(y)` (the latter only because the model writes both).
    fy: Vec<f64>,
    gy: Vec<f64>,
    /// `grad ~h` at the predicted sample, then `J_f(y)^T grad ~h(z0)`.
    grad: Vec<f64>,
    jt: Vec<f64>,
    /// The row's state coefficients `c` (`L = c^T g(s)`), for the robust tightening too.
    pub(super) coefficients: Vec<f64>,
}

/// One barrier as its sampled row reads it: `~h = sign * predicate - margin`, and its value at
/// the state.
#[derive(Clone, Copy)]
pub(super) struct Barrier<'a> {
    pub(super) predicate: &'a Predicate,
    pub(super) sign: f64,
    /// `h(s)` (the sign applied, the margin not).
    pub(super) h: f64,
}

impl Barrier<'_> {
    fn shifted(&self, s: &[f64], margin: f64) -> f64 {
        self.sign * self.predicate.value(s) - margin
    }
}

impl Sampled {
    fn resize(&mut self, n: usize) {
        for buf in [
            &mut self.y,
            &mut self.y0,
            &mut self.z,
            &mut self.fy,
            &mut self.grad,
            &mut self.jt,
            &mut self.coefficients,
        ] {
            buf.resize(n, 0.0);
        }
    }

    /// Predicts this step's samples, once for every barrier: `y = s + dt f(s)` from the
    /// drift-included `f`, and, under a model (whose drift `drift`, constant over the step,
    /// moves the dimensions no input does), `z0 = y0 + dt f(y0)` for the second-order rows,
    /// `y0` the step of the action `a0` (with `g` = `g(s)`) under a model that bends the step
    /// and a non-empty `a0`, else `y` (the step of `a = 0`).
    pub(super) fn predict(
        &mut self,
        s: &[f64],
        (f, g): (&[f64], &[f64]),
        model: Option<&Dynamics>,
        (drift, a0): (Option<&[f64]>, &[f64]),
        dt: f64,
    ) {
        let n = s.len();
        self.resize(n);
        for ((y, &si), &fi) in self.y.iter_mut().zip(s).zip(f) {
            *y = si + dt * fi;
        }
        let Some(model) = model else {
            self.bent = false;
            return;
        };
        self.bent = model.bends_step();
        self.y0.copy_from_slice(&self.y);
        if self.bent && !a0.is_empty() {
            let m = a0.len();
            for (k, y0) in self.y0.iter_mut().enumerate() {
                let push = (0..m).map(|j| g[k * m + j] * a0[j]).sum::<f64>();
                *y0 = s[k] + dt * (f[k] + push);
            }
        }
        self.gy.resize(n * model.inputs(), 0.0);
        model.eval(&self.y0, &mut self.fy, &mut self.gy);
        if let Some(d) = drift {
            self.fy.iter_mut().zip(d).for_each(|(f, d)| *f += d);
        }
        for ((z, &y), &fy) in self.z.iter_mut().zip(&self.y0).zip(&self.fy) {
            *z = y + dt * fy;
        }
    }

    /// The first-order row of barrier `b` at this step's [`Sampled::predict`]: fills
    /// [`Sampled::coefficients`] and returns `r` (see the module docs).
    pub(super) fn first(
        &mut self,
        b: Barrier<'_>,
        s: &[f64],
        params: &ShieldParams,
        dt: f64,
    ) -> f64 {
        b.predicate.gradient_into(&self.y, &mut self.coefficients);
        self.coefficients.iter_mut().for_each(|c| *c *= b.sign);
        // The change over the step read by one code path (0 exactly when y = s).
        let change = b.shifted(&self.y, params.margin) - b.shifted(s, params.margin);
        change / dt + params.alpha * (b.h - params.margin)
    }

    /// The second-order row of barrier `b` at this step's [`Sampled::predict`] (made with
    /// `model`): fills [`Sampled::coefficients`] and returns `r`, read at `z0` (see the module
    /// docs; when [`Sampled::bent`], the row is `r + L . (a - a0) >= 0`).
    pub(super) fn second(
        &mut self,
        b: Barrier<'_>,
        s: &[f64],
        model: &Dynamics,
        params: &ShieldParams,
        dt: f64,
    ) -> f64 {
        b.predicate.gradient_into(&self.z, &mut self.grad);
        self.grad.iter_mut().for_each(|g| *g *= b.sign);
        model.jacobian_f_transpose_times(&self.y0, &self.grad, &mut self.jt);
        for ((c, &g), &j) in self.coefficients.iter_mut().zip(&self.grad).zip(&self.jt) {
            *c = (g + dt * j) / dt;
        }
        let alpha2 = params.alpha2.expect("Orders requires alpha2");
        let h_y = b.shifted(&self.y, params.margin);
        let psi = (h_y - b.shifted(s, params.margin)) / dt + params.alpha * (b.h - params.margin);
        let psi_next = (b.shifted(&self.z, params.margin) - h_y) / dt + params.alpha * h_y;
        (psi_next - psi) / dt + alpha2 * psi
    }
}

//! A user's own control-affine model `ds/dt = f(s) + g(s) a`, whose values come with every
//! shield call (the caller evaluates `f`, `g` and the drift's Jacobian `J_f` at the state).
//! What the shield must know before the first call is the model's structure: which state
//! dimensions an input moves directly (rows of `g` that are not identically zero), and which
//! through one integration (`f[d]` depends on such a dimension). From it every barrier gets
//! its relative degree (`shield/order.rs`), as under a built-in model.
//!
//! The structure is given, or found by [`CustomModel::probe`]: the union of the non-zeros of
//! `g` and `J_f` over a fixed set of states. A union over several generic states cannot miss a
//! dependence that holds on an open set, which is what "not identically zero" means for the
//! smooth models the shield supports.

use crate::alloc::{checked_len, try_vec, try_with_capacity};
use crate::check::check_finite;
use crate::error::InputError;

/// The structure of a user's control-affine model over `n` state values and `m` inputs.
#[derive(Debug, Clone, PartialEq)]
pub struct CustomModel {
    n: usize,
    m: usize,
    actuated: Vec<bool>,
    integrated: Vec<bool>,
}

/// How many states [`CustomModel::probe`] evaluates by default.
pub const PROBES: usize = 8;

/// The default probe states: `count` states of length `n`, uniform in `[-2, 2]`, from a fixed
/// seed (the same on every machine), so the structure found never depends on the run.
/// A size past memory is [`InputError::TooLarge`], not an abort.
pub fn probe_states(n: usize, count: usize) -> Result<Vec<f64>, InputError> {
    let len = checked_len(
        "ControlAffine probe states (state_dim x probes)",
        &[n, count],
    )?;
    let mut out = try_with_capacity("ControlAffine probe states", len)?;
    // splitmix64: a fixed, portable sequence.
    let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
    out.extend((0..len).map(|_| {
        x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = x;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        -2.0 + 4.0 * (z >> 11) as f64 / (1u64 << 53) as f64
    }));
    Ok(out)
}

/// Central differences of `f` at `s`: `out` (n x n, row-major) `[i][j] = df_i/ds_j`, with step
/// `h = eps^(1/3) (1 + |s_j|)` (about `6e-6`: it balances the `h^2` truncation error against
/// rounding), divided by the width actually stepped. Accurate to about `1e-10` relative for
/// smooth `f`; a dimension `f_i` does not read gives exactly 0 (both sides evaluate the same
/// expression).
pub fn jacobian_by_differences<E>(
    s: &[f64],
    mut f: impl FnMut(&[f64], &mut [f64]) -> Result<(), E>,
    out: &mut [f64],
) -> Result<(), E> {
    let n = s.len();
    let (mut x, mut plus, mut minus) = (s.to_vec(), vec![0.0; n], vec![0.0; n]);
    for j in 0..n {
        let h = f64::EPSILON.cbrt() * (1.0 + s[j].abs());
        let (hi, lo) = (s[j] + h, s[j] - h);
        x[j] = hi;
        f(&x, &mut plus)?;
        x[j] = lo;
        f(&x, &mut minus)?;
        x[j] = s[j];
        let width = hi - lo;
        for i in 0..n {
            out[i * n + j] = (plus[i] - minus[i]) / width;
        }
    }
    Ok(())
}

impl CustomModel {
    /// Checks a model's sizes before anything is built for them: at least one state value
    /// and one input.
    pub fn check_sizes(n: usize, m: usize) -> Result<(), InputError> {
        if n == 0 || m == 0 {
            return Err(InputError::Value {
                what: "ControlAffine state_dim, inputs".into(),
                expected: "at least one state value and one input".into(),
                got: format!("state_dim={n}, inputs={m}"),
            });
        }
        Ok(())
    }

    /// A model over `n` state values and `m` inputs whose inputs move the dimensions
    /// `actuated` directly and `integrated` through one integration.
    pub fn new(
        n: usize,
        m: usize,
        actuated: &[usize],
        integrated: &[usize],
    ) -> Result<Self, InputError> {
        Self::check_sizes(n, m)?;
        let mark = |what: &str, dims: &[usize]| -> Result<Vec<bool>, InputError> {
            let mut out = try_vec("ControlAffine state_dim", n, false)?;
            for &d in dims {
                if d >= n {
                    return Err(InputError::Value {
                        what: format!("ControlAffine {what}"),
                        expected: format!("state dimensions below {n}"),
                        got: format!("{dims:?}"),
                    });
                }
                out[d] = true;
            }
            Ok(out)
        };
        let actuated = mark("actuated", actuated)?;
        if !actuated.contains(&true) {
            return Err(InputError::Value {
                what: "ControlAffine g".into(),
                expected: "an input that moves some state dimension (g is zero everywhere)".into(),
                got: "no actuated dimension".into(),
            });
        }
        Ok(CustomModel {
            n,
            m,
            actuated,
            integrated: mark("integrated", integrated)?,
        })
    }

    /// The structure of the model `eval(s, f, g, jacobian)` evaluates (`f` n, `g` n x m and
    /// `J_f` n x n, row-major), found at the `states` (`k x n`, row-major): a dimension is
    /// actuated when its row of `g` is non-zero at some state, and integrated when `f` there
    /// depends on an actuated dimension at some state. Non-finite values are an error naming
    /// the state.
    pub fn probe<E: From<InputError>>(
        n: usize,
        m: usize,
        states: &[f64],
        mut eval: impl FnMut(&[f64], &mut [f64], &mut [f64], &mut [f64]) -> Result<(), E>,
    ) -> Result<Self, E> {
        if n == 0 || states.is_empty() || states.len() % n != 0 {
            return Err(InputError::Shape {
                what: "ControlAffine probe states".into(),
                expected: format!("one or more states of {n} values"),
                got: format!("{} values", states.len()),
            }
            .into());
        }
        // Sized by the user: a size past memory is an error, not an abort.
        let (nm, nn) = (
            checked_len("ControlAffine g (state_dim x inputs)", &[n, m])?,
            checked_len("ControlAffine jacobian (state_dim x state_dim)", &[n, n])?,
        );
        let mut f = try_vec("ControlAffine f (state_dim)", n, 0.0)?;
        let mut g = try_vec("ControlAffine g (state_dim x inputs)", nm, 0.0)?;
        let mut jac = try_vec("ControlAffine jacobian (state_dim x state_dim)", nn, 0.0)?;
        let mut actuated = try_vec("ControlAffine state_dim", n, false)?;
        let mut reads = try_vec("ControlAffine jacobian (state_dim x state_dim)", nn, false)?;
        for s in states.chunks_exact(n) {
            eval(s, &mut f, &mut g, &mut jac)?;
            let at = |what: &str| format!("ControlAffine {what} at the probe state {s:?}");
            check_finite(&at("f"), &f, n)?;
            check_finite(&at("g"), &g, m.max(1))?;
            check_finite(&at("jacobian"), &jac, n)?;
            for d in 0..n {
                actuated[d] |= g[d * m..(d + 1) * m].iter().any(|&v| v != 0.0);
            }
            for (r, &v) in reads.iter_mut().zip(&jac) {
                *r |= v != 0.0;
            }
        }
        let integrated: Vec<usize> = (0..n)
            .filter(|&d| (0..n).any(|j| actuated[j] && reads[d * n + j]))
            .collect();
        let actuated: Vec<usize> = (0..n).filter(|&d| actuated[d]).collect();
        Ok(Self::new(n, m, &actuated, &integrated)?)
    }

    /// One Euler step `s + dt (f + g a)` with `f` (n) and `g` (n x m) evaluated at `s` by the
    /// caller: the plant of an environment built on this model. Checks `a` and `dt`.
    pub fn checked_euler_step(
        &self,
        s: &[f64],
        a: &[f64],
        dt: f64,
        f: &[f64],
        g: &[f64],
    ) -> Result<Vec<f64>, InputError> {
        crate::dynamics::check_step_input(a, self.m, dt)?;
        let m = self.m;
        Ok((0..self.n)
            .map(|i| s[i] + dt * (f[i] + (0..m).map(|j| g[i * m + j] * a[j]).sum::<f64>()))
            .collect())
    }

    /// Number of state values n.
    pub fn state_len(&self) -> usize {
        self.n
    }

    /// Number of inputs m.
    pub fn inputs(&self) -> usize {
        self.m
    }

    /// The dimensions an input moves directly.
    pub fn actuated(&self) -> Vec<usize> {
        (0..self.n).filter(|&d| self.actuated[d]).collect()
    }

    /// The dimensions an input moves through one integration.
    pub fn integrated(&self) -> Vec<usize> {
        (0..self.n).filter(|&d| self.integrated[d]).collect()
    }
}

impl crate::dynamics::Structure for CustomModel {
    fn actuates(&self, d: usize) -> bool {
        self.actuated.get(d).copied().unwrap_or(false)
    }

    fn actuates_twice_removed(&self, d: usize) -> bool {
        self.integrated.get(d).copied().unwrap_or(false)
    }
}

/// The model as the relative-degree messages name it.
impl std::fmt::Display for CustomModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "ControlAffine(state_dim={}, inputs={}; actuated {:?}, integrated {:?})",
            self.n,
            self.m,
            self.actuated(),
            self.integrated()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dynamics::{Dynamics, Structure};

    /// Probing a built-in model's own `f`, `g` and Jacobian finds the built-in structure.
    #[test]
    fn probe_finds_the_structure_of_every_built_in_model() {
        let n = 5;
        for model in [
            Dynamics::double_integrator(vec![0, 1], vec![3, 2]).unwrap(),
            Dynamics::acceleration_unicycle(4, 1, 2, 0).unwrap(),
            Dynamics::unicycle(0.1, 0, 1, 2).unwrap(),
            Dynamics::single_integrator(vec![1, 4]).unwrap(),
            Dynamics::kinematic_bicycle(0.5, 0, 1, 2, 3).unwrap(),
        ] {
            let m = model.inputs();
            let probed = CustomModel::probe::<InputError>(
                n,
                m,
                &probe_states(n, PROBES).unwrap(),
                |s, f, g, jac| {
                    model.eval(s, f, g);
                    let mut fd = |x: &[f64], out: &mut [f64]| {
                        let mut g = vec![0.0; n * m];
                        model.eval(x, out, &mut g);
                        Ok::<(), InputError>(())
                    };
                    jacobian_by_differences(s, &mut fd, jac)
                },
            )
            .unwrap();
            for d in 0..n {
                assert_eq!(probed.actuates(d), model.actuates(d), "{model} dim {d}");
                assert_eq!(
                    probed.actuates_twice_removed(d),
                    model.actuates_twice_removed(d),
                    "{model} dim {d}"
                );
            }
        }
    }

    #[test]
    fn differences_match_the_exact_jacobian() {
        let model = Dynamics::kinematic_bicycle(0.5, 0, 1, 2, 3).unwrap();
        let s = [0.3, -1.0, 0.7, 1.4];
        let mut jac = [0.0; 16];
        jacobian_by_differences::<InputError>(
            &s,
            |x, out| {
                model.eval(x, out, &mut [0.0; 8]);
                Ok(())
            },
            &mut jac,
        )
        .unwrap();
        for j in 0..4 {
            let mut e = [0.0; 4];
            e[j] = 1.0;
            let mut col = [0.0; 4];
            model.jacobian_f_times(&s, &e, &mut col);
            for i in 0..4 {
                assert!((jac[i * 4 + j] - col[i]).abs() < 1e-8, "[{i}][{j}]");
            }
        }
    }

    #[test]
    fn bad_structures() {
        crate::tests_support::assert_error(
            CustomModel::new(0, 1, &[], &[]),
            "Value",
            "ControlAffine state_dim, inputs",
        );
        crate::tests_support::assert_error(
            CustomModel::new(2, 0, &[0], &[]),
            "Value",
            "ControlAffine state_dim, inputs",
        );
        crate::tests_support::assert_error(
            CustomModel::new(2, 1, &[2], &[]),
            "Value",
            "ControlAffine actuated",
        );
        crate::tests_support::assert_error(
            CustomModel::new(2, 1, &[], &[0]),
            "Value",
            "ControlAffine g",
        );
        let nan = CustomModel::probe::<InputError>(2, 1, &[0.0, 0.0], |_, f, _, _| {
            f[0] = f64::NAN;
            Ok(())
        });
        assert!(nan.unwrap_err().to_string().contains("probe state"));
    }
}

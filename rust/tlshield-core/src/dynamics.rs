//! Control-affine dynamics `ds/dt = f(s) + g(s) a` for the shield: a single integrator, the
//! unicycle reference point of the paper (Eq. 6A2), or `f`, `g` supplied by the caller.

use crate::error::InputError;

/// A built-in control-affine model over a state of length `n` with `m` inputs.
#[derive(Debug, Clone, PartialEq)]
pub enum Dynamics {
    /// `ds[pos[i]]/dt = a[i]`; every other state value has zero drift and no input.
    SingleIntegrator {
        /// The state dimensions driven by the inputs (m = pos.len()).
        pos: Vec<usize>,
    },
    /// The unicycle's reference point `eps` ahead of its centre (paper Eq. 6A2):
    /// `[dx, dy] = R(theta) diag(1, eps) [a_v, a_theta]`, `dtheta = a_theta`; m = 2.
    Unicycle {
        /// Distance of the reference point ahead of the centre (> 0).
        eps: f64,
        /// State index of the reference point's x.
        x: usize,
        /// State index of the reference point's y.
        y: usize,
        /// State index of the heading.
        theta: usize,
    },
}

impl Dynamics {
    /// A single integrator on `pos` (non-empty, distinct dimensions).
    pub fn single_integrator(pos: Vec<usize>) -> Result<Self, InputError> {
        if pos.is_empty() || (1..pos.len()).any(|i| pos[..i].contains(&pos[i])) {
            return Err(InputError::Shape {
                what: "SingleIntegrator pos".into(),
                expected: "at least one distinct state dimension".into(),
                got: format!("{pos:?}"),
            });
        }
        Ok(Dynamics::SingleIntegrator { pos })
    }

    /// The unicycle reference point; `eps` finite and > 0, `x`, `y`, `theta` distinct.
    pub fn unicycle(eps: f64, x: usize, y: usize, theta: usize) -> Result<Self, InputError> {
        if !(eps.is_finite() && eps > 0.0) {
            return Err(InputError::Shape {
                what: "Unicycle eps".into(),
                expected: "a finite distance > 0".into(),
                got: eps.to_string(),
            });
        }
        if x == y || x == theta || y == theta {
            return Err(InputError::Shape {
                what: "Unicycle dimensions".into(),
                expected: "distinct x, y, theta".into(),
                got: format!("x={x}, y={y}, theta={theta}"),
            });
        }
        Ok(Dynamics::Unicycle { eps, x, y, theta })
    }

    /// Number of inputs m.
    pub fn inputs(&self) -> usize {
        match self {
            Dynamics::SingleIntegrator { pos } => pos.len(),
            Dynamics::Unicycle { .. } => 2,
        }
    }

    /// The smallest state length the model can read.
    pub fn min_dim(&self) -> usize {
        match self {
            Dynamics::SingleIntegrator { pos } => pos.iter().max().map_or(0, |m| m + 1),
            Dynamics::Unicycle { x, y, theta, .. } => *x.max(y).max(theta) + 1,
        }
    }

    /// Writes `f(s)` (length n) and `g(s)` (n x m, row-major) for state `s`.
    pub fn eval(&self, s: &[f64], f: &mut [f64], g: &mut [f64]) {
        f.fill(0.0);
        g.fill(0.0);
        let m = self.inputs();
        match self {
            Dynamics::SingleIntegrator { pos } => {
                for (i, &p) in pos.iter().enumerate() {
                    g[p * m + i] = 1.0;
                }
            }
            Dynamics::Unicycle { eps, x, y, theta } => {
                let (sin, cos) = s[*theta].sin_cos();
                g[x * m] = cos;
                g[x * m + 1] = -eps * sin;
                g[y * m] = sin;
                g[y * m + 1] = eps * cos;
                g[theta * m + 1] = 1.0;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unicycle_reference_point_matches_eq_6a2() {
        let d = Dynamics::unicycle(0.1, 0, 1, 2).unwrap();
        let s = [0.0, 0.0, std::f64::consts::FRAC_PI_2];
        let (mut f, mut g) = ([9.0; 3], [9.0; 6]);
        d.eval(&s, &mut f, &mut g);
        assert_eq!(f, [0.0; 3]);
        // theta = 90 degrees: a_v moves +y, a_theta moves the reference point -x by eps.
        let expect = [0.0, -0.1, 1.0, 0.0, 0.0, 1.0];
        for (a, b) in g.iter().zip(expect) {
            assert!((a - b).abs() < 1e-15);
        }
    }

    #[test]
    fn bad_models() {
        assert!(Dynamics::unicycle(0.0, 0, 1, 2).is_err());
        assert!(Dynamics::unicycle(0.1, 0, 0, 2).is_err());
        assert!(Dynamics::single_integrator(vec![]).is_err());
        assert!(Dynamics::single_integrator(vec![1, 1]).is_err());
    }
}

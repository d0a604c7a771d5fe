//! Vector-Jacobian products through a solved QP `min 1/2 x'Px + c'x  s.t.  G x <= h`.
//!
//! On a neighbourhood where the set `A` of active rows does not change, the solution solves the
//! KKT system restricted to `A`,
//!
//! ```text
//! [ P    G_A' ] [ x   ]   [ -c  ]
//! [ G_A  0    ] [ z_A ] = [ h_A ]
//! ```
//!
//! so it is affine in `h` and smooth in `G` and `c` (Amos & Kolter's OptNet, restricted to the
//! active rows). For an upstream gradient `v = dL/dx`, solve `K [w; omega] = [v; 0]` (`K` is
//! symmetric); then `dL/dh_A = omega`, `dL/dG_A = -(z_A w' + omega x')`, `dL/dc = -w`, and
//! every inactive row gets zero.
//!
//! Which rows are active: every tight row (or one with a positive multiplier), an
//! independent subset of them taken by decreasing multiplier, and the multipliers are
//! recomputed from the KKT system on that subset. The answer is the derivative of the piece on
//! which every tight row stays tight. Away from a change of active set that piece is the only
//! one and the derivative is two-sided and exact. At a change, a tight row has a zero
//! multiplier (weakly active) or depends on the others: the answer is then one of the one-sided
//! derivatives, flagged as [`Adjoint::degenerate`]. A row the caller knows to be implied by the
//! others (`implied`) is taken last and is no sign of degeneracy when it depends on them.
//!
//! The workspace's buffers only grow: nothing is allocated once it has seen the shape.

use crate::linalg::dot;
use crate::qp::DenseQp;

/// Rows whose multiplier is at most this fraction of `max(1, max_i z_i)` count as inactive.
pub const MULTIPLIER_TOL: f64 = 1e-8;
/// A row is tight when `h_i - G_i x` is at most this, relative to `1 + |h_i| + sum_j |G_ij x_j|`.
const TIGHT_TOL: f64 = 1e-9;
/// A unit row whose part outside the span of the rows already taken is below this is dependent.
const DEPENDENT: f64 = 1e-9;
/// Relative pivot threshold of the KKT factorisation.
const PIVOT_TOL: f64 = 1e-13;

/// What a vector-Jacobian product found about the solution it differentiated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Adjoint {
    /// A tight row had a zero multiplier, or an active row depended on the others: the
    /// derivative is one-sided (the piece on which those rows are inactive).
    pub degenerate: bool,
}

/// The KKT system was singular on the active rows (the solution is not locally unique).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Singular;

/// Reusable workspace for [`QpAdjointSolver::vjp`].
#[derive(Debug, Clone, Default)]
pub struct QpAdjointSolver {
    /// Active rows, in the order they were taken.
    active: Vec<usize>,
    /// Candidate rows sorted by decreasing multiplier.
    order: Vec<usize>,
    /// Orthonormal basis of the active rows' span (rows of length n).
    basis: Vec<f64>,
    /// The KKT matrix (d x d, row-major), overwritten by its LU factors.
    kkt: Vec<f64>,
    /// Right-hand side, then `[w; omega]`.
    sol: Vec<f64>,
    /// Row interchanges of the factorisation.
    piv: Vec<usize>,
    /// The active rows' multipliers, from the KKT system.
    multipliers: Vec<f64>,
}

impl QpAdjointSolver {
    /// An empty workspace (the shield's gradient keeps one per workspace, by `Default`).
    #[cfg(test)]
    pub fn new() -> Self {
        Self::default()
    }

    /// `dh = dL/dh` (length rows) and `dg = dL/dG` (rows x n, row-major) for `dx = dL/dx` at
    /// the solution `x` with multipliers `z` (`z >= 0`, as [`crate::qp::QpSolution`] gives
    /// them). `implied` names a row the others imply whenever it is tight (see the module
    /// docs). The slices must have the problem's sizes. [`factor`](Self::factor) then
    /// [`apply`](Self::apply), for one upstream gradient.
    #[cfg(test)]
    #[allow(clippy::too_many_arguments)]
    pub fn vjp(
        &mut self,
        qp: &DenseQp,
        x: &[f64],
        z: &[f64],
        dx: &[f64],
        implied: Option<usize>,
        dh: &mut [f64],
        dg: &mut [f64],
    ) -> Result<Adjoint, Singular> {
        let adjoint = self.factor(qp, x, z, implied)?;
        self.apply(qp, x, dx, dh, dg);
        Ok(adjoint)
    }

    /// Chooses the active rows at the solution `x` (multipliers `z`) and factors their KKT
    /// system, for any number of [`apply`](Self::apply) calls.
    pub fn factor(
        &mut self,
        qp: &DenseQp,
        x: &[f64],
        z: &[f64],
        implied: Option<usize>,
    ) -> Result<Adjoint, Singular> {
        let n = qp.vars();
        debug_assert!(x.len() == n && z.len() == qp.rows());
        let mut adjoint = Adjoint {
            degenerate: self.choose_active(qp, x, z, implied),
        };

        // K = [P G_A'; G_A 0]; the multipliers from K [x; z_A] = [-c; h_A], then
        // K [w; omega] = [dx; 0].
        let na = self.active.len();
        let d = n + na;
        self.kkt.clear();
        self.kkt.resize(d * d, 0.0);
        for j in 0..n {
            self.kkt[j * d + j] = qp.p_diag[j];
        }
        for (k, &i) in self.active.iter().enumerate() {
            for j in 0..n {
                let g = qp.g[i * n + j];
                self.kkt[(n + k) * d + j] = g;
                self.kkt[j * d + n + k] = g;
            }
        }
        self.factor_kkt(d)?;
        self.sol.clear();
        self.sol.extend(qp.c.iter().map(|c| -c));
        self.sol.extend(self.active.iter().map(|&i| qp.h[i]));
        self.solve(d);
        self.multipliers.clear();
        self.multipliers.extend_from_slice(&self.sol[n..]);
        let lmax = self.multipliers.iter().fold(1.0_f64, |a, &b| a.max(b));
        adjoint.degenerate |= self.multipliers.iter().any(|&l| l <= MULTIPLIER_TOL * lmax);
        Ok(adjoint)
    }

    /// Chooses the active rows at `x` (multipliers `z`): the tight rows, `implied` last, then
    /// by decreasing multiplier, keeping those independent of the ones before
    /// (Gram-Schmidt, twice for stability). Returns whether a tight row was dropped as
    /// dependent (other than `implied`).
    fn choose_active(
        &mut self,
        qp: &DenseQp,
        x: &[f64],
        z: &[f64],
        implied: Option<usize>,
    ) -> bool {
        let n = qp.vars();
        let mut degenerate = false;
        let zmax = z.iter().fold(1.0_f64, |a, &b| a.max(b));
        let ztol = MULTIPLIER_TOL * zmax;

        // Tight rows, the implied one last, then by decreasing multiplier.
        self.order.clear();
        for (i, &zi) in z.iter().enumerate() {
            let row = &qp.g[i * n..(i + 1) * n];
            let scale =
                1.0 + qp.h[i].abs() + row.iter().zip(x).map(|(g, x)| (g * x).abs()).sum::<f64>();
            let tight = qp.h[i] - dot(row, x) <= TIGHT_TOL * scale;
            if zi > ztol || (tight && row.iter().any(|&g| g != 0.0)) {
                self.order.push(i);
            }
        }
        let key = |i: usize| (Some(i) == implied, -z[i]);
        self.order.sort_by(|&a, &b| {
            key(a)
                .partial_cmp(&key(b))
                .unwrap_or(std::cmp::Ordering::Equal)
        });

        // Gram-Schmidt (twice, for stability) keeps the independent ones.
        self.active.clear();
        self.basis.clear();
        for k in 0..self.order.len() {
            let i = self.order[k];
            let start = self.basis.len();
            let row = &qp.g[i * n..(i + 1) * n];
            let norm = dot(row, row).sqrt();
            self.basis.extend(row.iter().map(|g| g / norm));
            for _ in 0..2 {
                for b in 0..self.active.len() {
                    let (done, new) = self.basis.split_at_mut(start);
                    let e = &done[b * n..(b + 1) * n];
                    let p = dot(e, new);
                    new.iter_mut().zip(e).for_each(|(v, e)| *v -= p * e);
                }
            }
            let rest = dot(&self.basis[start..], &self.basis[start..]).sqrt();
            if rest < DEPENDENT {
                self.basis.truncate(start);
                degenerate |= Some(i) != implied;
                continue;
            }
            self.basis[start..].iter_mut().for_each(|v| *v /= rest);
            self.active.push(i);
        }

        degenerate
    }

    /// `dh = dL/dh` and `dg = dL/dG` for `dx = dL/dx` with the factors of the last
    /// [`factor`](Self::factor) (same problem and solution).
    pub fn apply(&mut self, qp: &DenseQp, x: &[f64], dx: &[f64], dh: &mut [f64], dg: &mut [f64]) {
        let n = qp.vars();
        debug_assert!(dx.len() == n && dh.len() == qp.rows() && dg.len() == qp.rows() * n);
        dh.fill(0.0);
        dg.fill(0.0);
        let d = n + self.active.len();
        self.sol.clear();
        self.sol.extend_from_slice(dx);
        self.sol.resize(d, 0.0);
        self.solve(d);
        let (w, omega) = self.sol.split_at(n);
        for (k, &i) in self.active.iter().enumerate() {
            dh[i] = omega[k];
            for j in 0..n {
                dg[i * n + j] = -(self.multipliers[k] * w[j] + omega[k] * x[j]);
            }
        }
    }

    /// LU factors of the d x d `kkt` with partial pivoting, in place.
    fn factor_kkt(&mut self, d: usize) -> Result<(), Singular> {
        let a = &mut self.kkt;
        let scale = a.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        if scale == 0.0 && d > 0 {
            return Err(Singular);
        }
        self.piv.clear();
        for col in 0..d {
            let (p, best) = (col..d)
                .map(|r| (r, a[r * d + col].abs()))
                .fold((col, -1.0), |acc, x| if x.1 > acc.1 { x } else { acc });
            if best <= PIVOT_TOL * scale {
                return Err(Singular);
            }
            self.piv.push(p);
            if p != col {
                for j in 0..d {
                    a.swap(col * d + j, p * d + j);
                }
            }
            let pivot = a[col * d + col];
            for r in col + 1..d {
                let f = a[r * d + col] / pivot;
                a[r * d + col] = f;
                if f != 0.0 {
                    for j in col + 1..d {
                        a[r * d + j] -= f * a[col * d + j];
                    }
                }
            }
        }
        Ok(())
    }

    /// `sol <- kkt^{-1} sol` with the factors of [`factor_kkt`](Self::factor_kkt).
    fn solve(&mut self, d: usize) {
        let a = &self.kkt;
        // The factors are of P K (whole rows were swapped): permute, then L, then U.
        for col in 0..d {
            self.sol.swap(col, self.piv[col]);
        }
        for col in 0..d {
            let v = self.sol[col];
            for r in col + 1..d {
                self.sol[r] -= a[r * d + col] * v;
            }
        }
        for r in (0..d).rev() {
            let s = (r + 1..d).map(|j| a[r * d + j] * self.sol[j]).sum::<f64>();
            self.sol[r] = (self.sol[r] - s) / a[r * d + r];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::active_set::ActiveSetQp;
    use crate::qp::QpStatus;
    use proptest::prelude::*;

    /// `L(x) = v . x*(qp)` by central differences in `h_i` and `G_ij`.
    fn fd(qp: &DenseQp, v: &[f64], eps: f64) -> (Vec<f64>, Vec<f64>) {
        let value = |qp: &DenseQp| {
            let sol = ActiveSetQp::new().solve(qp);
            assert_eq!(sol.status, QpStatus::Solved);
            dot(v, &sol.x)
        };
        let mut dh = vec![0.0; qp.rows()];
        for (i, out) in dh.iter_mut().enumerate() {
            let (mut p, mut m) = (qp.clone(), qp.clone());
            p.h[i] += eps;
            m.h[i] -= eps;
            *out = (value(&p) - value(&m)) / (2.0 * eps);
        }
        let mut dg = vec![0.0; qp.g.len()];
        for (k, out) in dg.iter_mut().enumerate() {
            let (mut p, mut m) = (qp.clone(), qp.clone());
            p.g[k] += eps;
            m.g[k] -= eps;
            *out = (value(&p) - value(&m)) / (2.0 * eps);
        }
        (dh, dg)
    }

    /// `min |x - t|^2 + k d` over a box and a few random rows with a slack `d >= 0` on one.
    fn problem(t: &[f64], rows: &[f64], rhs: &[f64]) -> DenseQp {
        let n = t.len();
        let mut g = Vec::new();
        let mut h = Vec::new();
        for (r, &b) in rows.chunks(n).zip(rhs) {
            g.extend_from_slice(r);
            g.push(0.0);
            h.push(b);
        }
        // The first row may be relaxed by d.
        g[n] = -1.0;
        for j in 0..n {
            for sign in [1.0, -1.0] {
                let mut r = vec![0.0; n + 1];
                r[j] = sign;
                g.extend(r);
                h.push(1.0);
            }
        }
        let mut r = vec![0.0; n + 1];
        r[n] = -1.0;
        g.extend(r);
        h.push(0.0);
        let mut p = vec![2.0; n];
        p.push(0.0);
        let mut c: Vec<f64> = t.iter().map(|t| -2.0 * t).collect();
        c.push(3.0);
        DenseQp { p_diag: p, c, g, h }
    }

    #[test]
    fn one_active_bound_by_hand() {
        // min x^2 s.t. -x <= -t: x = t, dx/dt = 1, so dL/dh = -1 and dL/dG = t.
        let t = 0.7;
        let qp = DenseQp {
            p_diag: vec![2.0],
            c: vec![0.0],
            g: vec![-1.0],
            h: vec![-t],
        };
        let sol = ActiveSetQp::new().solve(&qp);
        let (mut dh, mut dg) = (vec![0.0], vec![0.0]);
        let adj = QpAdjointSolver::new()
            .vjp(&qp, &sol.x, &sol.z, &[1.0], None, &mut dh, &mut dg)
            .unwrap();
        assert!(!adj.degenerate);
        assert!(
            (dh[0] + 1.0).abs() < 1e-12 && (dg[0] - t).abs() < 1e-12,
            "{dh:?} {dg:?}"
        );
    }

    #[test]
    fn weakly_active_row_is_flagged() {
        // min (x - 1)^2 s.t. x <= 1: tight with a zero multiplier.
        let qp = DenseQp {
            p_diag: vec![2.0],
            c: vec![-2.0],
            g: vec![1.0],
            h: vec![1.0],
        };
        let sol = ActiveSetQp::new().solve(&qp);
        let (mut dh, mut dg) = (vec![0.0], vec![0.0]);
        let adj = QpAdjointSolver::new()
            .vjp(&qp, &sol.x, &sol.z, &[1.0], None, &mut dh, &mut dg)
            .unwrap();
        // The piece on which the row stays tight: x = h, so dL/dh = 1 (one-sided).
        assert!(adj.degenerate);
        assert!((dh[0] - 1.0).abs() < 1e-12, "{dh:?}");
    }

    proptest! {
        #![proptest_config(crate::tests_support::seeded(64))]
        #[test]
        fn matches_finite_differences(
            t in proptest::collection::vec(-2.0..2.0f64, 3),
            rows in proptest::collection::vec(-1.0..1.0f64, 6),
            rhs in proptest::collection::vec(-0.5..0.5f64, 2),
            v in proptest::collection::vec(-1.0..1.0f64, 4),
        ) {
            let qp = problem(&t, &rows, &rhs);
            let sol = ActiveSetQp::new().solve(&qp);
            prop_assume!(sol.status == QpStatus::Solved);
            let (mut dh, mut dg) = (vec![0.0; qp.rows()], vec![0.0; qp.g.len()]);
            let mut adjoint = QpAdjointSolver::new();
            let adj = adjoint.vjp(&qp, &sol.x, &sol.z, &v, None, &mut dh, &mut dg);
            prop_assume!(adj.is_ok_and(|a| !a.degenerate));
            // Away from a change of active set: no row within 1e-4 of switching.
            let n = qp.vars();
            let margin = (0..qp.rows()).all(|i| {
                let slack = qp.h[i] - dot(&qp.g[i * n..(i + 1) * n], &sol.x);
                slack > 1e-4 || sol.z[i] > 1e-4
            });
            prop_assume!(margin);
            let (fh, fg) = fd(&qp, &v, 1e-7);
            for (a, b) in dh.iter().zip(&fh).chain(dg.iter().zip(&fg)) {
                prop_assert!((a - b).abs() < 1e-6 * (1.0 + b.abs()), "{a} vs {b}");
            }
        }
    }
}

//! Exact dense active-set solver for small QPs `min 1/2 x'Px + c'x  s.t.  G x <= h` with a
//! diagonal `P >= 0` (the shield QP: a few actions plus a linear-cost slack), meant to answer in
//! microseconds and to hand anything doubtful back to [`ClarabelQp`](crate::qp::ClarabelQp).
//!
//! Design:
//! 1. Rows are scaled to unit norm. A zero row is skipped when `h >= 0` and proves
//!    infeasibility otherwise; so is a row whose plane is farther than `FAR` (1e12) from the
//!    origin (it cannot bind, and it would set the problem's length scale).
//! 2. Identification: Goldfarb–Idnani dual active set (no feasible start, independent working
//!    rows) on a strictly convex surrogate. Zero or tiny `P_jj` become
//!    `eps_j = max(|c_j| / X, 1e-8 p_ref)` with `X = 1e6 x length scale`, so a linear cost moves
//!    by ~1e-6 of itself across the problem. Such variables start pinned at their tightest
//!    single-variable bound against the cost (delta >= 0), a valid dual start that keeps the
//!    iterates at the problem's scale. A violated row that is a non-negative combination of
//!    working rows yields a Farkas certificate, checked, then `Infeasible`.
//! 3. Polish: the exact KKT system of the ORIGINAL problem on that working set is solved by LU
//!    with partial pivoting plus one refinement step. A negative multiplier (drop the row) or
//!    a violated row (add it) corrects the working set, a bounded number of times.
//! 4. `Solved` is returned only after the KKT conditions of the original data hold to 1e-9
//!    relative. Anything else is `Failed`: singular systems, cycling, iteration limits,
//!    n > [`MAX_VARS`], non-finite data.
//! 5. Dense storage is fixed-capacity nalgebra matrices, and the per-row buffers only grow:
//!    [`ActiveSetQp::solve_into`] allocates nothing once it has seen the shape.

use nalgebra::{SMatrix, SVector};

use crate::linalg::dot;
use crate::qp::{DenseQp, QpSolution, QpStatus};

/// Largest number of variables [`ActiveSetQp`] accepts; larger problems return `Failed`.
pub const MAX_VARS: usize = 16;

/// Capacity of the KKT system: `n` variables plus at most `n` independent working rows.
const KKT_DIM: usize = 2 * MAX_VARS;
/// Length-scale multiple at which the surrogate's proximal term equals a variable's linear cost.
const REG_RANGE: f64 = 1e6;
/// Floor of the proximal term, relative to the problem's curvature scale.
const REG_FLOOR: f64 = 1e-8;
/// Rows violated by less than this, relative to the largest iterate, end the dual method
/// (rounding of `b - a'x`); the polish step then settles them exactly.
const GI_TOL: f64 = 1e-14;
/// A row whose direction in the free subspace is below this fraction is linearly dependent.
const DEPENDENT: f64 = 1e-10;
/// Relative tolerance of the final KKT certificate.
const KKT_TOL: f64 = 1e-9;
/// Relative pivot threshold of the KKT factorisation (against the column's largest entry).
const PIVOT_TOL: f64 = 1e-14;
/// A row whose plane lies farther than this from the origin, on the side of it that holds the
/// origin (`h / |row| > FAR`, in `x`'s units), cannot bind at any point the problem reaches.
/// It is set aside like a zero row with `h >= 0`: kept, it would set the length scale
/// (`bmax`) that the surrogate and the certificate's tolerance read, and a barrier row whose
/// gradient is orthogonal to the input up to rounding (coefficients ~1e-16) made that
/// tolerance 1e8 and certified a wrong point.
const FAR: f64 = 1e12;

/// Fixed-capacity dense storage (boxed once so the solver itself stays small to move).
#[derive(Debug, Clone)]
struct Dense {
    /// Goldfarb–Idnani `J = L^{-T} Q` (top-left `n x n` used).
    j: SMatrix<f64, MAX_VARS, MAX_VARS>,
    /// Upper-triangular `R` with `J' N = [R; 0]` (top-left `q x q` used).
    r: SMatrix<f64, MAX_VARS, MAX_VARS>,
    /// KKT matrix, overwritten by its LU factors.
    kkt: SMatrix<f64, KKT_DIM, KKT_DIM>,
    /// Right-hand side / solution of the KKT system.
    sol: SVector<f64, KKT_DIM>,
    /// Refinement right-hand side / correction.
    res: SVector<f64, KKT_DIM>,
    /// Largest entry of each KKT column before factorisation.
    col_max: [f64; KKT_DIM],
    /// Row interchanges of the LU factorisation (LAPACK convention).
    piv: [usize; KKT_DIM],
}

impl Dense {
    fn new() -> Self {
        Dense {
            j: SMatrix::zeros(),
            r: SMatrix::zeros(),
            kkt: SMatrix::zeros(),
            sol: SVector::zeros(),
            res: SVector::zeros(),
            col_max: [0.0; KKT_DIM],
            piv: [0; KKT_DIM],
        }
    }
}

/// Exact dense active-set QP solver with a reusable workspace (see the module docs).
///
/// ```
/// use tlshield_core::active_set::ActiveSetQp;
/// use tlshield_core::qp::{DenseQp, QpStatus};
///
/// // min a^2 + 1e4 d  s.t.  a + d >= 1, d >= 0, a <= 0.25  ->  a = 0.25, d = 0.75.
/// let qp = DenseQp {
///     p_diag: vec![2.0, 0.0],
///     c: vec![0.0, 1e4],
///     g: vec![-1.0, -1.0, 0.0, -1.0, 1.0, 0.0],
///     h: vec![-1.0, 0.0, 0.25],
/// };
/// let sol = ActiveSetQp::new().solve(&qp);
/// assert_eq!(sol.status, QpStatus::Solved);
/// assert!((sol.x[0] - 0.25).abs() < 1e-12 && (sol.x[1] - 0.75).abs() < 1e-12);
/// ```
#[derive(Debug, Clone)]
pub struct ActiveSetQp {
    dense: Box<Dense>,
    /// Diagonal of the strictly convex surrogate.
    preg: [f64; MAX_VARS],
    x: [f64; MAX_VARS],
    /// `J' n_p` for the row being added.
    d: [f64; MAX_VARS],
    /// Primal step direction.
    step: [f64; MAX_VARS],
    /// Dual step direction.
    rdir: [f64; MAX_VARS],
    /// Multipliers of the working rows (surrogate during identification, exact after polish).
    u: [f64; MAX_VARS],
    /// Working rows, in the order of the columns of `R`.
    active: [usize; MAX_VARS],
    /// Number of working rows.
    q: usize,
    /// Unit-norm rows (row-major, rows x n).
    a: Vec<f64>,
    /// Right-hand sides of the unit-norm rows.
    b: Vec<f64>,
    /// Row norms of `G` (0 for zero rows, which are skipped).
    norm: Vec<f64>,
    /// Whether a row is in the working set.
    in_set: Vec<bool>,
    /// Largest `|b_i|`.
    bmax: f64,
    /// Steps taken by the current solve.
    iterations: u32,
}

impl Default for ActiveSetQp {
    fn default() -> Self {
        Self::new()
    }
}

impl ActiveSetQp {
    /// An empty workspace; buffers grow to the largest shape seen.
    pub fn new() -> Self {
        ActiveSetQp {
            dense: Box::new(Dense::new()),
            preg: [0.0; MAX_VARS],
            x: [0.0; MAX_VARS],
            d: [0.0; MAX_VARS],
            step: [0.0; MAX_VARS],
            rdir: [0.0; MAX_VARS],
            u: [0.0; MAX_VARS],
            active: [0; MAX_VARS],
            q: 0,
            a: Vec::new(),
            b: Vec::new(),
            norm: Vec::new(),
            in_set: Vec::new(),
            bmax: 0.0,
            iterations: 0,
        }
    }

    /// Solves `qp`. `Solved` only with a verified KKT point of the original problem;
    /// `Infeasible` only with a verified Farkas certificate; otherwise `Failed`.
    pub fn solve(&mut self, qp: &DenseQp) -> QpSolution {
        let mut out = QpSolution {
            status: QpStatus::Failed,
            x: Vec::new(),
            z: Vec::new(),
            iterations: 0,
        };
        self.solve_into(qp, &mut out);
        out
    }

    /// Like [`solve`](Self::solve), writing into `out` (its vectors are resized, which does not
    /// allocate once they have held a solution of this size).
    pub fn solve_into(&mut self, qp: &DenseQp, out: &mut QpSolution) {
        let (n, rows) = (qp.c.len(), qp.h.len());
        out.x.clear();
        out.x.resize(n, 0.0);
        out.z.clear();
        out.z.resize(rows, 0.0);
        self.iterations = 0;
        let status = self.run(qp, out);
        if status != QpStatus::Solved {
            out.x.iter_mut().for_each(|v| *v = 0.0);
            out.z.iter_mut().for_each(|v| *v = 0.0);
        }
        out.status = status;
        out.iterations = self.iterations;
    }

    fn run(&mut self, qp: &DenseQp, out: &mut QpSolution) -> QpStatus {
        let (n, rows) = (qp.c.len(), qp.h.len());
        if qp.p_diag.len() != n || rows.checked_mul(n) != Some(qp.g.len()) {
            return QpStatus::Failed;
        }
        let finite = [&qp.p_diag, &qp.c, &qp.g, &qp.h]
            .iter()
            .all(|v| v.iter().all(|x| x.is_finite()));
        if !finite || qp.p_diag.iter().any(|&p| p < 0.0) {
            return QpStatus::Failed;
        }
        if n == 0 {
            return if qp.h.iter().all(|&h| h >= 0.0) {
                QpStatus::Solved
            } else {
                QpStatus::Infeasible
            };
        }
        if n > MAX_VARS {
            return QpStatus::Failed;
        }
        if let Err(status) = self.normalise_rows(qp) {
            return status;
        }
        if !self.regularise(qp) {
            return QpStatus::Failed;
        }
        if let Err(status) = self.dual_active_set(qp) {
            return status;
        }
        self.polish(qp, out)
    }

    /// Fills the unit-norm rows; a zero row with `h < 0` proves infeasibility, and a zero
    /// row with `h >= 0` or a row beyond [`FAR`] is set aside (norm 0).
    fn normalise_rows(&mut self, qp: &DenseQp) -> Result<(), QpStatus> {
        let (n, rows) = (qp.vars(), qp.rows());
        self.a.clear();
        self.b.clear();
        self.norm.clear();
        self.in_set.clear();
        self.in_set.resize(rows, false);
        self.bmax = 0.0;
        for (row, &h) in qp.g.chunks_exact(n).zip(&qp.h) {
            let big = row.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            if big == 0.0 {
                if h < 0.0 {
                    return Err(QpStatus::Infeasible);
                }
                self.a.extend(row.iter().map(|_| 0.0));
                self.b.push(0.0);
                self.norm.push(0.0);
                continue;
            }
            // Scaled 2-norm: no overflow or underflow for any finite row.
            let norm = big
                * row
                    .iter()
                    .map(|v| (v / big) * (v / big))
                    .sum::<f64>()
                    .sqrt();
            let inv = 1.0 / norm;
            let b = h * inv;
            if b > FAR {
                self.a.extend(row.iter().map(|_| 0.0));
                self.b.push(0.0);
                self.norm.push(0.0);
                continue;
            }
            self.a.extend(row.iter().map(|v| v * inv));
            if !b.is_finite() {
                return Err(QpStatus::Failed);
            }
            self.bmax = self.bmax.max(b.abs());
            self.b.push(b);
            self.norm.push(norm);
        }
        Ok(())
    }

    /// The strictly convex surrogate's diagonal (see the module docs).
    fn regularise(&mut self, qp: &DenseQp) -> bool {
        let n = qp.vars();
        let mut length = self.bmax;
        let mut pmax = 0.0f64;
        for (&p, &c) in qp.p_diag.iter().zip(&qp.c) {
            pmax = pmax.max(p);
            if p > 0.0 {
                length = length.max((c / p).abs());
            }
        }
        if !(length > 0.0 && length.is_finite()) {
            length = 1.0;
        }
        let range = REG_RANGE * length;
        let cmax = qp.c.iter().fold(0.0f64, |m, c| m.max(c.abs()));
        let mut p_ref = pmax.max(cmax / range);
        if p_ref == 0.0 {
            p_ref = 1.0;
        }
        for j in 0..n {
            let eps = (qp.c[j].abs() / range).max(REG_FLOOR * p_ref);
            let p = qp.p_diag[j].max(eps);
            if !(p.is_finite() && p > 0.0) {
                return false;
            }
            self.preg[j] = p;
        }
        true
    }

    /// Goldfarb–Idnani on the surrogate: leaves its working set in `active[..q]`.
    fn dual_active_set(&mut self, qp: &DenseQp) -> Result<(), QpStatus> {
        let (n, rows) = (qp.vars(), qp.rows());
        let dense = &mut *self.dense;
        for jj in 0..n {
            for ii in 0..n {
                dense.j[(ii, jj)] = 0.0;
            }
            dense.j[(jj, jj)] = 1.0 / self.preg[jj].sqrt();
            self.x[jj] = -qp.c[jj] / self.preg[jj];
        }
        self.q = 0;
        self.crash(qp);
        // Rounding in s = b - a'x is relative to the largest iterate.
        let mut xscale = self.x[..n].iter().fold(self.bmax, |m, v| m.max(v.abs()));
        let max_iter = 20 + 10 * (n + rows) as u64;
        let mut steps = 0u64;
        loop {
            // Step 1: the most violated row not in the working set.
            let mut p = usize::MAX;
            let mut sp = -GI_TOL * xscale - f64::MIN_POSITIVE;
            for i in 0..rows {
                if self.in_set[i] || self.norm[i] == 0.0 {
                    continue;
                }
                let s = self.b[i] - dot(&self.a[i * n..(i + 1) * n], &self.x[..n]);
                if s < sp {
                    sp = s;
                    p = i;
                }
            }
            if p == usize::MAX {
                return Ok(());
            }
            let mut up = 0.0;
            loop {
                steps += 1;
                self.iterations = self.iterations.saturating_add(1);
                if steps > max_iter {
                    return Err(QpStatus::Failed);
                }
                let q = self.q;
                let (dn2, d2n2) = self.direction(p, n);
                let dense = &mut *self.dense;
                // Primal direction z = J2 d2, dual direction r = R^{-1} d1.
                for ii in 0..n {
                    self.step[ii] = (q..n).map(|jj| dense.j[(ii, jj)] * self.d[jj]).sum();
                }
                for ii in (0..q).rev() {
                    let mut s = self.d[ii];
                    for k in ii + 1..q {
                        s -= dense.r[(ii, k)] * self.rdir[k];
                    }
                    self.rdir[ii] = s / dense.r[(ii, ii)];
                }
                // Partial (dual) step t1 and full step t2.
                let (mut t1, mut l) = (f64::INFINITY, usize::MAX);
                for k in 0..q {
                    if self.rdir[k] > 0.0 {
                        let t = (self.u[k] / self.rdir[k]).max(0.0);
                        if t < t1 {
                            t1 = t;
                            l = k;
                        }
                    }
                }
                // A row (numerically) in the span of the working rows has no primal step.
                let independent = d2n2 > DEPENDENT * DEPENDENT * dn2;
                let t2 = if independent {
                    (-sp / d2n2).max(0.0)
                } else {
                    f64::INFINITY
                };
                if t1.is_nan() || t2.is_nan() {
                    return Err(QpStatus::Failed);
                }
                if !t1.is_finite() && !t2.is_finite() {
                    return Err(self.farkas(p, n));
                }
                if !t2.is_finite() {
                    // Step in the dual space only, then drop the blocking row.
                    for k in 0..q {
                        self.u[k] -= t1 * self.rdir[k];
                    }
                    up += t1;
                    self.drop_row(l, n);
                    continue;
                }
                let t = t1.min(t2);
                for ii in 0..n {
                    self.x[ii] += t * self.step[ii];
                    xscale = xscale.max(self.x[ii].abs());
                }
                for k in 0..q {
                    self.u[k] -= t * self.rdir[k];
                }
                up += t;
                if t2 <= t1 {
                    if !self.add_row(p, up, n) {
                        return Err(QpStatus::Failed);
                    }
                    break;
                }
                self.drop_row(l, n);
                sp = self.b[p] - dot(&self.a[p * n..(p + 1) * n], &self.x[..n]);
            }
        }
    }

    /// Crash start: every regularised variable with a linear cost is pinned at its tightest
    /// single-variable bound row opposing that cost (delta >= 0 in the shield). Bounds on
    /// distinct variables are independent, and the pinned point is the surrogate's optimum on
    /// them with multipliers `-(c_j + eps_j x_j) / a_ij >= 0`, so this is a valid dual start. It
    /// keeps the iterates at the problem's own scale instead of starting from `-c_j / eps_j`.
    fn crash(&mut self, qp: &DenseQp) {
        let (n, rows) = (qp.vars(), qp.rows());
        for jj in 0..n {
            let c = qp.c[jj];
            if self.preg[jj] <= qp.p_diag[jj] || c == 0.0 {
                continue;
            }
            // Moving against the cost means moving along -sign(c): the tightest bound is the
            // one with the smallest -sign(c) * bound.
            let mut best: Option<(usize, f64)> = None;
            for i in 0..rows {
                let row = &self.a[i * n..(i + 1) * n];
                if self.in_set[i] || self.norm[i] == 0.0 || row[jj] * c >= 0.0 {
                    continue;
                }
                if row.iter().enumerate().any(|(k, v)| k != jj && *v != 0.0) {
                    continue;
                }
                let bound = self.b[i] / row[jj];
                if best.is_none_or(|(_, b)| -c.signum() * bound < -c.signum() * b) {
                    best = Some((i, bound));
                }
            }
            let Some((i, bound)) = best else { continue };
            let multiplier = -(c + self.preg[jj] * bound) / self.a[i * n + jj];
            if !(multiplier > 0.0 && multiplier.is_finite()) {
                continue;
            }
            self.x[jj] = bound;
            self.direction(i, n);
            if !self.add_row(i, multiplier, n) {
                // Cannot happen for independent bounds; fall back to the plain start.
                return;
            }
        }
    }

    /// `d = J' n_p` for row `p` (its ">=" normal is `-a_p`); returns `|d|^2` and `|d[q..]|^2`.
    fn direction(&mut self, p: usize, n: usize) -> (f64, f64) {
        let ap = &self.a[p * n..(p + 1) * n];
        let (mut dn2, mut d2n2) = (0.0, 0.0);
        for jj in 0..n {
            let s = -dot_col(&self.dense.j, jj, ap);
            self.d[jj] = s;
            dn2 += s * s;
            if jj >= self.q {
                d2n2 += s * s;
            }
        }
        (dn2, d2n2)
    }

    /// Adds row `p` with multiplier `up`, using `d = J' n_p`: Givens reflections zero `d[q+1..]`
    /// (applied to the columns of `J`) and `d[..=q]` becomes the new column of `R`.
    fn add_row(&mut self, p: usize, up: f64, n: usize) -> bool {
        let q = self.q;
        let dense = &mut *self.dense;
        for jj in (q + 1..n).rev() {
            let (d0, d1) = (self.d[jj - 1], self.d[jj]);
            if d1 == 0.0 {
                continue;
            }
            let h = (d0 * d0 + d1 * d1).sqrt();
            let (cc, ss) = (d0 / h, d1 / h);
            self.d[jj - 1] = h;
            self.d[jj] = 0.0;
            reflect_cols(&mut dense.j, n, jj - 1, cc, ss);
        }
        if !(self.d[q].abs() > 0.0 && self.d[q].is_finite()) {
            return false;
        }
        for ii in 0..=q {
            dense.r[(ii, q)] = self.d[ii];
        }
        self.active[q] = p;
        self.u[q] = up.max(0.0);
        self.in_set[p] = true;
        self.q = q + 1;
        true
    }

    /// Removes the working row at position `l`, restoring the triangular `R` with Givens
    /// reflections (applied to the columns of `J` too).
    fn drop_row(&mut self, l: usize, n: usize) {
        let q = self.q;
        let dense = &mut *self.dense;
        self.in_set[self.active[l]] = false;
        for k in l..q - 1 {
            self.active[k] = self.active[k + 1];
            self.u[k] = self.u[k + 1];
            for ii in 0..=k + 1 {
                dense.r[(ii, k)] = dense.r[(ii, k + 1)];
            }
        }
        let q = q - 1;
        self.q = q;
        for jj in l..q {
            let (r0, r1) = (dense.r[(jj, jj)], dense.r[(jj + 1, jj)]);
            if r1 == 0.0 {
                continue;
            }
            let h = (r0 * r0 + r1 * r1).sqrt();
            let (cc, ss) = (r0 / h, r1 / h);
            dense.r[(jj, jj)] = h;
            dense.r[(jj + 1, jj)] = 0.0;
            for k in jj + 1..q {
                let (t0, t1) = (dense.r[(jj, k)], dense.r[(jj + 1, k)]);
                dense.r[(jj, k)] = cc * t0 + ss * t1;
                dense.r[(jj + 1, k)] = ss * t0 - cc * t1;
            }
            reflect_cols(&mut dense.j, n, jj, cc, ss);
        }
    }

    /// The violated row `p` is `sum r_k a_k` over the working rows with every `r_k <= 0`, so
    /// `y = (1 at p, -r_k at the working rows) >= 0` has `A'y = 0` and `b'y < 0`. Checked before
    /// it is believed.
    fn farkas(&self, p: usize, n: usize) -> QpStatus {
        let q = self.q;
        let mut ysum = 1.0;
        let mut gap = self.b[p];
        let mut bsum = self.b[p].abs();
        for k in 0..q {
            let r = self.rdir[k];
            if r > 0.0 {
                return QpStatus::Failed;
            }
            let i = self.active[k];
            ysum -= r;
            gap -= r * self.b[i];
            bsum += (r * self.b[i]).abs();
        }
        let mut resid = 0.0f64;
        for jj in 0..n {
            let mut v = self.a[p * n + jj];
            for k in 0..q {
                v -= self.rdir[k] * self.a[self.active[k] * n + jj];
            }
            resid = resid.max(v.abs());
        }
        if resid <= KKT_TOL * ysum && gap < -KKT_TOL * bsum {
            QpStatus::Infeasible
        } else {
            QpStatus::Failed
        }
    }

    /// Solves the original problem's KKT system on the working set, corrects the working set
    /// while a multiplier is negative or a row is violated, and certifies the result.
    fn polish(&mut self, qp: &DenseQp, out: &mut QpSolution) -> QpStatus {
        let (n, rows) = (qp.vars(), qp.rows());
        let cmax = qp.c.iter().fold(0.0f64, |m, c| m.max(c.abs()));
        for _ in 0..2 * n + 4 {
            if !self.solve_kkt(qp) {
                return QpStatus::Failed;
            }
            let x = &self.x[..n];
            let xmax = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let pxmax = x
                .iter()
                .zip(&qp.p_diag)
                .fold(0.0f64, |m, (v, p)| m.max((v * p).abs()));
            let (primal_scale, dual_scale) = (xmax.max(self.bmax), cmax.max(pxmax));
            let mut drop_at = None;
            let mut most_negative = -KKT_TOL * dual_scale;
            for k in 0..self.q {
                if self.u[k] < most_negative {
                    most_negative = self.u[k];
                    drop_at = Some(k);
                }
            }
            let mut add = None;
            let mut worst = KKT_TOL * primal_scale;
            for i in 0..rows {
                if self.in_set[i] || self.norm[i] == 0.0 {
                    continue;
                }
                let v = dot(&self.a[i * n..(i + 1) * n], x) - self.b[i];
                if v > worst {
                    worst = v;
                    add = Some(i);
                }
            }
            match (drop_at, add) {
                (None, None) => {
                    out.x.copy_from_slice(x);
                    for k in 0..self.q {
                        let i = self.active[k];
                        out.z[i] = self.u[k].max(0.0) / self.norm[i];
                    }
                    return if self.certify(qp, out) {
                        QpStatus::Solved
                    } else {
                        QpStatus::Failed
                    };
                }
                (Some(k), _) => {
                    self.in_set[self.active[k]] = false;
                    for t in k..self.q - 1 {
                        self.active[t] = self.active[t + 1];
                    }
                    self.q -= 1;
                }
                (None, Some(i)) => {
                    if self.q == n {
                        return QpStatus::Failed;
                    }
                    self.active[self.q] = i;
                    self.in_set[i] = true;
                    self.q += 1;
                }
            }
            self.iterations = self.iterations.saturating_add(1);
        }
        QpStatus::Failed
    }

    /// `[P A'; A 0] [x; u] = [-c; b]` on the working rows, by LU with partial pivoting and one
    /// step of iterative refinement. Writes `x` and `u`; false when singular.
    fn solve_kkt(&mut self, qp: &DenseQp) -> bool {
        let n = qp.vars();
        let q = self.q;
        let k = n + q;
        let dense = &mut *self.dense;
        for jj in 0..k {
            for ii in 0..k {
                dense.kkt[(ii, jj)] = 0.0;
            }
        }
        for jj in 0..n {
            dense.kkt[(jj, jj)] = qp.p_diag[jj];
            dense.sol[jj] = -qp.c[jj];
        }
        for t in 0..q {
            let i = self.active[t];
            for jj in 0..n {
                let v = self.a[i * n + jj];
                dense.kkt[(n + t, jj)] = v;
                dense.kkt[(jj, n + t)] = v;
            }
            dense.sol[n + t] = self.b[i];
        }
        for jj in 0..k {
            dense.col_max[jj] = (0..k).fold(0.0f64, |m, ii| m.max(dense.kkt[(ii, jj)].abs()));
        }
        if !lu_factor(dense, k) {
            return false;
        }
        let Dense {
            kkt, sol, res, piv, ..
        } = dense;
        lu_solve(kkt, piv, sol, k);
        // Refinement: residual of the KKT equations from the structure, then one correction.
        for jj in 0..n {
            res[jj] = -qp.c[jj] - qp.p_diag[jj] * sol[jj];
        }
        for t in 0..q {
            let row = &self.a[self.active[t] * n..(self.active[t] + 1) * n];
            let ut = sol[n + t];
            let mut ax = 0.0;
            for jj in 0..n {
                res[jj] -= row[jj] * ut;
                ax += row[jj] * sol[jj];
            }
            res[n + t] = self.b[self.active[t]] - ax;
        }
        lu_solve(kkt, piv, res, k);
        for ii in 0..k {
            sol[ii] += res[ii];
            if !sol[ii].is_finite() {
                return false;
            }
        }
        self.x[..n].copy_from_slice(&sol.as_slice()[..n]);
        self.u[..q].copy_from_slice(&sol.as_slice()[n..k]);
        true
    }

    /// KKT conditions of the ORIGINAL data at `(out.x, out.z)`, relative to the problem's
    /// magnitude: every row violated by at most `KKT_TOL * primal scale` (in distance units),
    /// `z >= 0`, rows with `z > 0` tight to the same tolerance, and
    /// `|P x + c + G' z|_inf <= KKT_TOL * max(|P x|, |c|, |G' z| termwise)`.
    fn certify(&self, qp: &DenseQp, out: &QpSolution) -> bool {
        let n = qp.vars();
        let (x, z) = (&out.x, &out.z);
        let mut grad = [0.0f64; MAX_VARS];
        let mut mag = [0.0f64; MAX_VARS];
        for jj in 0..n {
            let px = qp.p_diag[jj] * x[jj];
            grad[jj] = px + qp.c[jj];
            mag[jj] = px.abs().max(qp.c[jj].abs());
        }
        if !x.iter().all(|v| v.is_finite()) {
            return false;
        }
        let primal_scale = x.iter().fold(self.bmax, |m, v| m.max(v.abs()));
        let tol = KKT_TOL * primal_scale;
        for (i, (row, &h)) in qp.g.chunks_exact(n).zip(&qp.h).enumerate() {
            let zi = z[i];
            if !(zi >= 0.0 && zi.is_finite()) {
                return false;
            }
            if self.norm[i] == 0.0 {
                if zi != 0.0 {
                    return false;
                }
                continue;
            }
            let gap = (dot(row, x) - h) / self.norm[i];
            // Written so that NaN fails.
            let feasible = gap <= tol;
            let complementary = zi == 0.0 || gap >= -tol;
            if !(feasible && complementary) {
                return false;
            }
            if zi > 0.0 {
                for jj in 0..n {
                    let v = row[jj] * zi;
                    grad[jj] += v;
                    mag[jj] += v.abs();
                }
            }
        }
        let scale = mag[..n].iter().fold(f64::MIN_POSITIVE, |m, v| m.max(*v));
        grad[..n].iter().all(|g| g.abs() <= KKT_TOL * scale)
    }
}

/// `J[.., col]' v` over the first `v.len()` rows.
fn dot_col(j: &SMatrix<f64, MAX_VARS, MAX_VARS>, col: usize, v: &[f64]) -> f64 {
    let column = &j.as_slice()[col * MAX_VARS..col * MAX_VARS + v.len()];
    dot(column, v)
}

/// Applies the symmetric reflection `[[cc, ss], [ss, -cc]]` to columns `col`, `col + 1` of `J`.
fn reflect_cols(j: &mut SMatrix<f64, MAX_VARS, MAX_VARS>, n: usize, col: usize, cc: f64, ss: f64) {
    for ii in 0..n {
        let (t0, t1) = (j[(ii, col)], j[(ii, col + 1)]);
        j[(ii, col)] = cc * t0 + ss * t1;
        j[(ii, col + 1)] = ss * t0 - cc * t1;
    }
}

/// In-place LU with partial pivoting of the leading `k x k` block of `dense.kkt`; false when a
/// pivot is negligible against its column's original magnitude.
fn lu_factor(dense: &mut Dense, k: usize) -> bool {
    let m = &mut dense.kkt;
    for col in 0..k {
        let (mut pr, mut best) = (col, m[(col, col)].abs());
        for ii in col + 1..k {
            let v = m[(ii, col)].abs();
            if v > best {
                best = v;
                pr = ii;
            }
        }
        let usable = best > PIVOT_TOL * dense.col_max[col] && best.is_finite();
        if !usable {
            return false;
        }
        dense.piv[col] = pr;
        if pr != col {
            for jj in 0..k {
                m.swap((col, jj), (pr, jj));
            }
        }
        let inv = 1.0 / m[(col, col)];
        for ii in col + 1..k {
            let f = m[(ii, col)] * inv;
            m[(ii, col)] = f;
            if f != 0.0 {
                for jj in col + 1..k {
                    let v = m[(col, jj)];
                    m[(ii, jj)] -= f * v;
                }
            }
        }
    }
    true
}

/// Solves with the factors of [`lu_factor`] in place.
fn lu_solve(
    m: &SMatrix<f64, KKT_DIM, KKT_DIM>,
    piv: &[usize; KKT_DIM],
    v: &mut SVector<f64, KKT_DIM>,
    k: usize,
) {
    for (col, &pr) in piv.iter().enumerate().take(k) {
        if pr != col {
            v.swap_rows(col, pr);
        }
    }
    for col in 0..k {
        let vc = v[col];
        if vc != 0.0 {
            for ii in col + 1..k {
                v[ii] -= m[(ii, col)] * vc;
            }
        }
    }
    for ii in (0..k).rev() {
        let mut s = v[ii];
        for jj in ii + 1..k {
            s -= m[(ii, jj)] * v[jj];
        }
        v[ii] = s / m[(ii, ii)];
    }
}

#[cfg(test)]
mod tests;

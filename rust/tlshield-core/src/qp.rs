//! Small dense quadratic programs `min 1/2 x'Px + c'x  s.t.  G x <= h` with a diagonal `P`,
//! solved by Clarabel (the solver of record). The problem structure (dimensions, sparsity, P)
//! is built once per shape and only the data (`c`, `G`, `h`) is updated per solve, so a shield
//! step reuses the solver's allocations.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus,
    SupportedConeT::NonnegativeConeT,
};

/// A QP instance: `n` variables, `rows` inequality rows.
#[derive(Debug, Clone, PartialEq)]
pub struct DenseQp {
    /// Diagonal of `P` (length n, non-negative).
    pub p_diag: Vec<f64>,
    /// Linear cost (length n).
    pub c: Vec<f64>,
    /// Inequality matrix, row-major (rows x n).
    pub g: Vec<f64>,
    /// Right-hand side (length rows).
    pub h: Vec<f64>,
}

impl DenseQp {
    /// Number of variables.
    pub fn vars(&self) -> usize {
        self.c.len()
    }

    /// Number of inequality rows.
    pub fn rows(&self) -> usize {
        self.h.len()
    }

    /// Largest violation of `G x <= h` (0 when feasible).
    pub fn max_violation(&self, x: &[f64]) -> f64 {
        let n = self.vars();
        (0..self.rows())
            .map(|i| {
                let gx: f64 = self.g[i * n..(i + 1) * n]
                    .iter()
                    .zip(x)
                    .map(|(a, b)| a * b)
                    .sum();
                (gx - self.h[i]).max(0.0)
            })
            .fold(0.0, f64::max)
    }

    /// The objective at `x`.
    pub fn objective(&self, x: &[f64]) -> f64 {
        x.iter()
            .zip(&self.p_diag)
            .zip(&self.c)
            .map(|((x, p), c)| 0.5 * p * x * x + c * x)
            .sum()
    }
}

/// How a solve ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QpStatus {
    /// Optimal to the solver's tolerances.
    Solved,
    /// The rows cannot all hold.
    Infeasible,
    /// Numerical trouble or iteration limit.
    Failed,
}

/// A primal-dual solution.
#[derive(Debug, Clone, PartialEq)]
pub struct QpSolution {
    /// How the solve ended.
    pub status: QpStatus,
    /// Primal solution (length n; zeros unless solved).
    pub x: Vec<f64>,
    /// Multipliers of the rows (length rows; zeros unless solved).
    pub z: Vec<f64>,
    /// Interior-point iterations.
    pub iterations: u32,
}

/// Clarabel, with a solver built for each problem. A solver kept per shape and updated in
/// place keeps the data scaling (equilibration) of the first problem it saw, so its answers
/// depended, in their last digits, on which problems that workspace had solved before, and
/// workspaces go to threads by timing: two runs of the same training differed (measured:
/// `tlshield reproduce` with two Ray workers). Clarabel is the fallback of the active-set
/// solver, so the cost of building it is paid on few steps.
pub struct ClarabelQp {
    settings: DefaultSettings<f64>,
    /// Column-major copy of G (Clarabel's CSC of a dense matrix), reused.
    nzval: Vec<f64>,
}

impl std::fmt::Debug for ClarabelQp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ClarabelQp").finish_non_exhaustive()
    }
}

impl Default for ClarabelQp {
    fn default() -> Self {
        Self::new()
    }
}

/// A dense CSC pattern (every entry structural, so updates never change the sparsity).
fn dense_csc(rows: usize, cols: usize, col_major: Vec<f64>) -> CscMatrix<f64> {
    let colptr = (0..=cols).map(|j| j * rows).collect();
    let rowval = (0..cols).flat_map(|_| 0..rows).collect();
    CscMatrix::new(rows, cols, colptr, rowval, col_major)
}

impl ClarabelQp {
    /// Settings chosen for exactness on small, possibly badly scaled problems: tight gap and
    /// feasibility tolerances (the linear penalty K * delta makes the default gap tolerance
    /// visible in the actions), presolve off and structural zeros kept so data updates are
    /// always accepted.
    pub fn new() -> Self {
        let settings = DefaultSettingsBuilder::default()
            .verbose(false)
            .tol_gap_abs(1e-10)
            .tol_gap_rel(1e-10)
            .tol_feas(1e-10)
            .tol_ktratio(1e-8)
            .presolve_enable(false)
            .input_sparse_dropzeros(false)
            .max_iter(100)
            .build()
            .expect("valid Clarabel settings");
        ClarabelQp {
            settings,
            nzval: Vec::new(),
        }
    }

    /// Solves `qp` with a solver built for it (see the type's docs: the answer depends on `qp`
    /// alone).
    pub fn solve(&mut self, qp: &DenseQp) -> QpSolution {
        let (n, rows) = (qp.vars(), qp.rows());
        let failed = |status| QpSolution {
            status,
            x: vec![0.0; n],
            z: vec![0.0; rows],
            iterations: 0,
        };
        if n == 0 {
            return QpSolution {
                status: if qp.h.iter().all(|&h| h >= 0.0) {
                    QpStatus::Solved
                } else {
                    QpStatus::Infeasible
                },
                ..failed(QpStatus::Solved)
            };
        }
        self.nzval.clear();
        for j in 0..n {
            self.nzval.extend((0..rows).map(|i| qp.g[i * n + j]));
        }
        let p = CscMatrix::new(n, n, (0..=n).collect(), (0..n).collect(), qp.p_diag.clone());
        let a = dense_csc(rows, n, self.nzval.clone());
        let cones = [NonnegativeConeT(rows)];
        let mut solver =
            match DefaultSolver::new(&p, &qp.c, &a, &qp.h, &cones, self.settings.clone()) {
                Ok(solver) => solver,
                Err(_) => return failed(QpStatus::Failed),
            };
        solver.solve();
        let sol = &solver.solution;
        let status = match sol.status {
            SolverStatus::Solved | SolverStatus::AlmostSolved => QpStatus::Solved,
            SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
                QpStatus::Infeasible
            }
            _ => QpStatus::Failed,
        };
        if status != QpStatus::Solved || sol.x.iter().any(|v| !v.is_finite()) {
            let mut out = failed(if status == QpStatus::Solved {
                QpStatus::Failed
            } else {
                status
            });
            out.iterations = sol.iterations;
            return out;
        }
        QpSolution {
            status,
            x: sol.x.clone(),
            z: sol.z.clone(),
            iterations: sol.iterations,
        }
    }
}

/// Largest violation of the KKT conditions of `qp` at `(x, z)`: primal feasibility, dual
/// feasibility (z >= 0), stationarity `P x + c + G' z = 0` and complementarity.
pub fn kkt_residual(qp: &DenseQp, x: &[f64], z: &[f64]) -> f64 {
    let n = qp.vars();
    let mut worst = qp.max_violation(x);
    worst = z.iter().fold(worst, |w, &zi| w.max(-zi));
    for (j, xj) in x.iter().enumerate() {
        let grad = qp.p_diag[j] * xj
            + qp.c[j]
            + z.iter()
                .enumerate()
                .map(|(i, zi)| qp.g[i * n + j] * zi)
                .sum::<f64>();
        worst = worst.max(grad.abs());
    }
    for (i, zi) in z.iter().enumerate() {
        let row = &qp.g[i * n..(i + 1) * n];
        let slack = qp.h[i] - row.iter().zip(x).map(|(a, b)| a * b).sum::<f64>();
        worst = worst.max((zi * slack).abs());
    }
    worst
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn box_constrained_projection() {
        // min |x - (3, -1)|^2 / 2 over x <= 1 (both coordinates): x = (1, -1).
        let qp = DenseQp {
            p_diag: vec![1.0, 1.0],
            c: vec![-3.0, 1.0],
            g: vec![1.0, 0.0, 0.0, 1.0],
            h: vec![1.0, 1.0],
        };
        let mut solver = ClarabelQp::new();
        let sol = solver.solve(&qp);
        assert_eq!(sol.status, QpStatus::Solved);
        assert!((sol.x[0] - 1.0).abs() < 1e-8 && (sol.x[1] + 1.0).abs() < 1e-8);
        assert!((sol.z[0] - 2.0).abs() < 1e-6, "{:?}", sol.z);
        assert!(kkt_residual(&qp, &sol.x, &sol.z) < 1e-7);
    }

    /// The answer to a problem is the same bit for bit whatever the solver solved before (a
    /// solver updated in place kept the first problem's scaling, and training runs whose steps
    /// met the workspaces in another order differed).
    #[test]
    fn an_answer_does_not_depend_on_earlier_problems() {
        let problem = |scale: f64| DenseQp {
            p_diag: vec![2.0, 2.0, 0.0],
            c: vec![0.0, 0.0, 1e4],
            g: vec![
                scale, 0.3, -1.0, //
                0.0, 0.0, -1.0, //
                1.0, 0.0, 0.0, //
                -1.0, 0.0, 0.0, //
                0.0, 1.0, 0.0, //
                0.0, -1.0, 0.0,
            ],
            h: vec![-0.7 * scale, 0.0, 2.0, 2.0, 2.0, 2.0],
        };
        let target = problem(0.9);
        let alone = ClarabelQp::new().solve(&target);
        assert_eq!(alone.status, QpStatus::Solved);
        let mut used = ClarabelQp::new();
        for scale in [1e3, 1e-3, 37.0] {
            used.solve(&problem(scale));
        }
        let after = used.solve(&target);
        assert_eq!(after, alone);
    }

    #[test]
    fn infeasible_rows_are_reported() {
        // x <= -1 and -x <= -1 (x >= 1).
        let qp = DenseQp {
            p_diag: vec![2.0],
            c: vec![0.0],
            g: vec![1.0, -1.0],
            h: vec![-1.0, -1.0],
        };
        let sol = ClarabelQp::new().solve(&qp);
        assert_eq!(sol.status, QpStatus::Infeasible);
        assert!(sol.x.iter().all(|v| *v == 0.0));
    }

    #[test]
    fn linear_penalty_variable_is_exact() {
        // min a^2 + K d  s.t.  -a - d <= -1 (a + d >= 1), d >= 0, a <= 0.25.
        // Optimum: a = 0.25, d = 0.75 (the bound binds and d pays the rest).
        let qp = DenseQp {
            p_diag: vec![2.0, 0.0],
            c: vec![0.0, 1e4],
            g: vec![-1.0, -1.0, 0.0, -1.0, 1.0, 0.0],
            h: vec![-1.0, 0.0, 0.25],
        };
        let sol = ClarabelQp::new().solve(&qp);
        assert_eq!(sol.status, QpStatus::Solved);
        assert!(
            (sol.x[0] - 0.25).abs() < 1e-7 && (sol.x[1] - 0.75).abs() < 1e-7,
            "{:?}",
            sol.x
        );
    }

    proptest! {
        #![proptest_config(crate::tests_support::seeded(300))]

        /// Random feasible problems (the origin box contains a feasible point by construction):
        /// Clarabel's answer satisfies the KKT conditions, with the solver reused across shapes.
        #[test]
        fn solutions_satisfy_kkt(
            n in 1usize..5,
            rows in 1usize..6,
            seed in prop::collection::vec(-1.0..1.0f64, 64),
        ) {
            let p_diag: Vec<f64> = (0..n).map(|j| 1.0 + seed[j].abs()).collect();
            let c: Vec<f64> = (0..n).map(|j| 3.0 * seed[8 + j]).collect();
            let g: Vec<f64> = (0..rows * n).map(|k| seed[16 + k % 40]).collect();
            // h >= |G| * 0.1 keeps a small ball around 0 feasible.
            let h: Vec<f64> = (0..rows)
                .map(|i| g[i * n..(i + 1) * n].iter().map(|v| v.abs()).sum::<f64>() * 0.1 + seed[56 + i % 8].abs())
                .collect();
            let qp = DenseQp { p_diag, c, g, h };
            let mut solver = ClarabelQp::new();
            for _ in 0..2 {
                let sol = solver.solve(&qp);
                prop_assert_eq!(sol.status, QpStatus::Solved);
                prop_assert!(kkt_residual(&qp, &sol.x, &sol.z) < 1e-6, "{}", kkt_residual(&qp, &sol.x, &sol.z));
            }
        }
    }
}

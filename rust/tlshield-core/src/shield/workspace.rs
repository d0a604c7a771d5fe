//! The per-thread workspace of shield steps: the rows, the QP, the two solvers and the last
//! answer, reused from step to step.

use crate::active_set::ActiveSetQp;
use crate::qp::{ClarabelQp, DenseQp, QpSolution, QpStatus};

use super::gradient;
use super::program::Program;
use super::{Filtered, SolvedBy, SolverChoice, ACTIVE_SET_MAX_VARS};

/// Reusable buffers and solvers for one thread of shield steps.
pub(super) struct Workspace {
    pub(super) program: Program,
    pub(super) qp: DenseQp,
    pub(super) solvers: Solvers,
    pub(super) out: Filtered,
    /// Buffers of the gradient pass (`gradient.rs`), empty until it first runs.
    pub(super) grad: gradient::Buffers,
}

/// The two QP solvers and the last solution.
pub(super) struct Solvers {
    pub(super) solution: QpSolution,
    pub(super) active_set: ActiveSetQp,
    pub(super) clarabel: ClarabelQp,
}

impl Solvers {
    /// Solves `qp` into `self.solution` with the chosen solver.
    pub(super) fn solve(&mut self, choice: SolverChoice, qp: &DenseQp) -> SolvedBy {
        let small = qp.vars() <= ACTIVE_SET_MAX_VARS;
        match choice {
            SolverChoice::ActiveSet => {
                self.active_set.solve_into(qp, &mut self.solution);
                SolvedBy::ActiveSet
            }
            SolverChoice::Auto if small => {
                self.active_set.solve_into(qp, &mut self.solution);
                if self.solution.status == QpStatus::Solved {
                    return SolvedBy::ActiveSet;
                }
                self.solution = self.clarabel.solve(qp);
                SolvedBy::Clarabel
            }
            _ => {
                self.solution = self.clarabel.solve(qp);
                SolvedBy::Clarabel
            }
        }
    }
}

impl Workspace {
    pub(super) fn new(n: usize, m: usize) -> Self {
        Workspace {
            program: Program::with_state_len(n),
            qp: DenseQp {
                p_diag: Vec::new(),
                c: Vec::new(),
                g: Vec::new(),
                h: Vec::new(),
            },
            solvers: Solvers {
                solution: QpSolution {
                    status: QpStatus::Failed,
                    x: Vec::new(),
                    z: Vec::new(),
                    iterations: 0,
                },
                active_set: ActiveSetQp::new(),
                clarabel: ClarabelQp::new(),
            },
            out: Filtered::new(m),
            grad: gradient::Buffers::default(),
        }
    }
}

//! What a shield step returns: its [`Status`], the solver that answered ([`SolvedBy`]), the
//! single step's [`Filtered`] and a batch's columns ([`BatchOutput`]).

use crate::cnf::Literal;
use crate::error::InputError;

/// How a shield step ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Status {
    /// The QP was solved as posed.
    Solved = 0,
    /// The barriers could not all hold; solved with slack on the barrier rows.
    Relaxed = 1,
    /// Even the relaxed problem failed; the corrections are zero.
    Failed = 2,
    /// The solver reported the problem as posed solved, but its answer broke a constraint by
    /// more than [`RESIDUAL_TOL`](super::RESIDUAL_TOL); the action is the relaxed problem's answer, which passed the
    /// same check (the largest slack is reported).
    Inaccurate = 3,
}

impl Status {
    /// Every status, in code order (the bindings build Python's `Status` from it).
    pub const ALL: [Status; 4] = [
        Status::Solved,
        Status::Relaxed,
        Status::Failed,
        Status::Inaccurate,
    ];

    /// `"solved"`, `"relaxed"`, `"failed"` or `"inaccurate"`.
    pub fn name(self) -> &'static str {
        match self {
            Status::Solved => "solved",
            Status::Relaxed => "relaxed",
            Status::Failed => "failed",
            Status::Inaccurate => "inaccurate",
        }
    }
}

/// Which solver produced the answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum SolvedBy {
    /// No QP (nothing to correct: both CBF and CLF off, or no rows at all), or failed.
    Nothing = 0,
    /// The dense active-set path.
    ActiveSet = 1,
    /// Clarabel.
    Clarabel = 2,
}

impl SolvedBy {
    /// Every solver, in code order (the bindings build Python's `Solver` from it).
    pub const ALL: [SolvedBy; 3] = [SolvedBy::Nothing, SolvedBy::ActiveSet, SolvedBy::Clarabel];

    /// `"none"`, `"active_set"` or `"clarabel"`.
    pub fn name(self) -> &'static str {
        match self {
            SolvedBy::Nothing => "none",
            SolvedBy::ActiveSet => "active_set",
            SolvedBy::Clarabel => "clarabel",
        }
    }
}

/// Where an enforced barrier comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BarrierSource {
    /// The user's barrier with this index in [`ShieldParams::barriers`](super::ShieldParams::barriers).
    User(usize),
    /// The literal kept from a clause of the FSA state's safe set.
    SafeSet(Literal),
}

/// The outcome of one shield step.
#[derive(Debug, Clone, PartialEq)]
pub struct Filtered {
    /// The action to apply: `a_rl + a_cbf + a_clf`.
    pub action: Vec<f64>,
    /// The safety correction (zeros when the CBF is off).
    pub a_cbf: Vec<f64>,
    /// The task correction (zeros when the CLF is off or there is no goal).
    pub a_clf: Vec<f64>,
    /// The CLF relaxation (0 when the CLF row holds).
    pub delta: f64,
    /// How the step ended.
    pub status: Status,
    /// The largest barrier slack (0 unless [`Status::Relaxed`]).
    pub slack: f64,
    /// When the QP was relaxed and a row took slack: the barrier whose row took the most, and
    /// that slack (the amount by which its condition was given up this step).
    pub gave_way: Option<(BarrierSource, f64)>,
    /// Which solver answered.
    pub solver: SolvedBy,
    /// The CLF goal this step, if any.
    pub goal: Option<Vec<f64>>,
    /// Whether this step's goal cannot be reached from the state, as far as the routing
    /// guidance can tell (it lies where the shield does not let the robot be, or no way
    /// around the avoided discs leads to it); false without a routed goal.
    pub goal_unreachable: bool,
    /// Every barrier enforced this step and its value `h(s)`.
    pub barriers: Vec<(BarrierSource, f64)>,
}

impl Filtered {
    pub(super) fn new(m: usize) -> Self {
        Filtered {
            action: vec![0.0; m],
            a_cbf: vec![0.0; m],
            a_clf: vec![0.0; m],
            delta: 0.0,
            status: Status::Solved,
            slack: 0.0,
            gave_way: None,
            solver: SolvedBy::Nothing,
            goal: None,
            goal_unreachable: false,
            barriers: Vec::new(),
        }
    }
}

/// Results of [`Shield::filter_batch`](super::Shield::filter_batch), one row per state (`m` values per row where the
/// quantity is a vector).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BatchOutput {
    /// Applied actions, `(B, m)` row-major.
    pub action: Vec<f64>,
    /// Safety corrections, `(B, m)`.
    pub a_cbf: Vec<f64>,
    /// Task corrections, `(B, m)`.
    pub a_clf: Vec<f64>,
    /// CLF relaxations, `(B,)`.
    pub delta: Vec<f64>,
    /// [`Status`] codes, `(B,)`.
    pub status: Vec<u8>,
    /// Largest barrier slack, `(B,)`.
    pub slack: Vec<f64>,
    /// [`SolvedBy`] codes, `(B,)`.
    pub solver: Vec<u8>,
    /// Per row, the barrier that gave way and its slack (see [`Filtered::gave_way`]).
    pub gave_way: Vec<Option<(BarrierSource, f64)>>,
}

impl BatchOutput {
    /// Sizes every column for `rows` rows of `m` inputs (reusing the buffers); a size that
    /// cannot be allocated is [`InputError::TooLarge`].
    pub(super) fn resize(&mut self, rows: usize, m: usize) -> Result<(), InputError> {
        let len = crate::alloc::checked_len("a_rl", &[rows, m])?;
        for column in [&mut self.action, &mut self.a_cbf, &mut self.a_clf] {
            crate::alloc::try_resize(column, "a_rl", len, 0.0)?;
        }
        crate::alloc::try_resize(&mut self.delta, "rows", rows, 0.0)?;
        crate::alloc::try_resize(&mut self.slack, "rows", rows, 0.0)?;
        crate::alloc::try_resize(&mut self.status, "rows", rows, 0)?;
        crate::alloc::try_resize(&mut self.gave_way, "rows", rows, None)?;
        crate::alloc::try_resize(&mut self.solver, "rows", rows, 0)
    }

    /// Views of consecutive runs of `chunk` rows (the last may be shorter), one per worker.
    pub(super) fn rows_mut(&mut self, chunk: usize, m: usize) -> impl Iterator<Item = OutRows<'_>> {
        self.action
            .chunks_mut(chunk * m)
            .zip(self.a_cbf.chunks_mut(chunk * m))
            .zip(self.a_clf.chunks_mut(chunk * m))
            .zip(self.delta.chunks_mut(chunk))
            .zip(self.status.chunks_mut(chunk))
            .zip(self.slack.chunks_mut(chunk))
            .zip(self.solver.chunks_mut(chunk))
            .zip(self.gave_way.chunks_mut(chunk))
            .map(
                |(((((((action, a_cbf), a_clf), delta), status), slack), solver), gave_way)| {
                    OutRows {
                        action,
                        a_cbf,
                        a_clf,
                        delta,
                        status,
                        slack,
                        solver,
                        gave_way,
                    }
                },
            )
    }
}

/// A run of consecutive rows of a [`BatchOutput`], written by one worker.
pub(super) struct OutRows<'a> {
    pub(super) action: &'a mut [f64],
    pub(super) a_cbf: &'a mut [f64],
    pub(super) a_clf: &'a mut [f64],
    pub(super) delta: &'a mut [f64],
    pub(super) status: &'a mut [u8],
    pub(super) slack: &'a mut [f64],
    pub(super) solver: &'a mut [u8],
    pub(super) gave_way: &'a mut [Option<(BarrierSource, f64)>],
}

impl OutRows<'_> {
    /// Row `i` of this run from one step's result.
    pub(super) fn write(&mut self, i: usize, m: usize, out: &Filtered) {
        let cols = i * m..(i + 1) * m;
        self.action[cols.clone()].copy_from_slice(&out.action);
        self.a_cbf[cols.clone()].copy_from_slice(&out.a_cbf);
        self.a_clf[cols].copy_from_slice(&out.a_clf);
        self.delta[i] = out.delta;
        self.status[i] = out.status as u8;
        self.slack[i] = out.slack;
        self.solver[i] = out.solver as u8;
        self.gave_way[i] = out.gave_way;
    }
}

/// The shield's answer in a world's step: the corrections and the solve's outcome in fixed-size
/// fields (a batch's rows allocate nothing), and the whole answer (goal, barriers) when the step
/// was asked to keep it ([`Shield::filter_step`](super::Shield::filter_step)).
#[derive(Debug, Clone, PartialEq)]
pub struct ShieldStep {
    /// The corrected action, `a_rl + a_cbf + a_clf`.
    pub action: [f64; 2],
    /// The safety correction.
    pub a_cbf: [f64; 2],
    /// The task correction.
    pub a_clf: [f64; 2],
    /// The CLF relaxation.
    pub delta: f64,
    /// The largest barrier slack.
    pub slack: f64,
    /// How the solve ended.
    pub status: Status,
    /// Which solver answered.
    pub solver: SolvedBy,
    /// The barrier that gave way and its slack, when the QP was relaxed.
    pub gave_way: Option<(BarrierSource, f64)>,
    /// The whole answer, when recorded.
    pub record: Option<Filtered>,
}

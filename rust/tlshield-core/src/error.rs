//! Error types, one enum per concern. Every error a caller can trigger is a value, never a panic.

use thiserror::Error;

/// A problem with a formula or with the predicates that give its atoms meaning.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SpecError {
    /// The formula text does not follow the grammar.
    #[error("parse error at column {column}: {message}\n  {formula}\n  {caret:>column$}")]
    Parse {
        /// 1-based column (in characters) where the problem starts.
        column: usize,
        /// What was expected and what was found.
        message: String,
        /// The formula text, for the rendered message.
        formula: String,
        /// Always `"^"`; kept as a field so the message can point at the column.
        caret: &'static str,
    },
    /// The formula parses but is not syntactically co-safe (not scTLTL).
    #[error("not an scTLTL formula (column {column}): {message}\n  {formula}\n  {caret:>column$}")]
    NotCoSafe {
        /// 1-based column of the offending operator.
        column: usize,
        /// Why the formula is rejected.
        message: String,
        /// The formula text, for the rendered message.
        formula: String,
        /// Always `"^"`.
        caret: &'static str,
    },
    /// Atoms of the formula that have no predicate.
    #[error("atom(s) without a predicate: {}", .0.join(", "))]
    MissingPredicates(Vec<String>),
    /// A predicate's parameters are invalid.
    #[error("invalid predicate: {0}")]
    InvalidPredicate(String),
    /// Two predicates disagree on the length of the state vector.
    #[error("predicates disagree on the state dimension: {0}")]
    InconsistentDimension(String),
}

impl SpecError {
    pub(crate) fn parse(formula: &str, column: usize, message: impl Into<String>) -> Self {
        SpecError::Parse {
            column,
            message: message.into(),
            formula: formula.to_string(),
            caret: "^",
        }
    }

    pub(crate) fn not_co_safe(formula: &str, column: usize, message: impl Into<String>) -> Self {
        SpecError::NotCoSafe {
            column,
            message: message.into(),
            formula: formula.to_string(),
            caret: "^",
        }
    }
}

/// A problem with numeric input data: shapes, non-finite values, out-of-range indices.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum InputError {
    /// An array has the wrong size along some axis (value-range problems are [`InputError::Value`]).
    #[error("{what}: expected {expected}, got {got}")]
    Shape {
        /// Which argument and axis.
        what: String,
        /// The size that was expected (may describe a range, e.g. "at least 3").
        expected: String,
        /// The size that was given.
        got: String,
    },
    /// A value outside its valid range (a parameter, an index or a setting).
    #[error("{what}: expected {expected}, got {got}")]
    Value {
        /// Which argument.
        what: String,
        /// What the valid values are.
        expected: String,
        /// The value that was given.
        got: String,
    },
    /// A size from the caller (rows, a count, an array to copy) that cannot be allocated: more
    /// than memory can hold or than `usize` can count.
    #[error("{what}: {count} items do not fit in memory{}", .bytes.map_or_else(|| " (their size overflows)".to_string(), |b| format!(" ({} requested)", human_bytes(b))))]
    TooLarge {
        /// Which argument.
        what: String,
        /// How many items were asked for (a product is written `a x b`).
        count: String,
        /// The bytes asked for, when that number fits in `usize`.
        bytes: Option<usize>,
    },
    /// An input value is NaN or infinite.
    #[error("{what} is {value} (all values must be finite)")]
    NonFinite {
        /// Which element, e.g. `traj[3, 1]`.
        what: String,
        /// The offending value.
        value: f64,
    },
}

/// A problem building or using an automaton.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum AutomatonError {
    /// The alphabet is the set of atom valuations; more than this many atoms is refused.
    #[error("the formula has {atoms} atoms; automata support at most {max}")]
    TooManyAtoms {
        /// Atoms of the formula.
        atoms: usize,
        /// The supported maximum.
        max: usize,
    },
    /// The automaton grew past the supported size: too many states, or too many decision-diagram
    /// nodes for its transitions.
    #[error(
        "the automaton is too large: {size} {what}, more than the {max} supported (split the \
         task, or use fewer independent subformulas)"
    )]
    TooLarge {
        /// What grew too large ("states", "decision-diagram nodes").
        what: &'static str,
        /// How many were reached.
        size: usize,
        /// The supported maximum.
        max: usize,
    },
    /// The build was stopped by its caller (a user's interrupt).
    #[error("the automaton build was interrupted")]
    Interrupted,
    /// The formula has more distinct temporal subformulas than the construction supports.
    #[error("the formula has more than {0} distinct temporal subformulas")]
    TooManyObligations(usize),
    /// A state id that does not exist.
    #[error("{what}: state {q} does not exist (the automaton has states 0..{num_states})")]
    UnknownState {
        /// Which argument.
        what: String,
        /// The id given.
        q: usize,
        /// Number of states.
        num_states: usize,
    },
    /// The trap state has no task reward (the environment pays a trap penalty there).
    #[error("q = {0} is the trap state, which has no task reward; pass trap_penalty to reward it")]
    TrapReward(usize),
    /// A task monitor was used before its episode started (`row`: which monitor of a batch);
    /// the one error for "not started", wherever a monitor is read.
    #[error("{}", not_reset(.row))]
    NotReset {
        /// The batch row, for a monitor of a batch.
        row: Option<usize>,
    },
    /// Bad numeric input.
    #[error(transparent)]
    Input(#[from] InputError),
}

/// A problem configuring or calling a shield.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ShieldError {
    /// A parameter of the shield is invalid (the message names it).
    #[error("{0}")]
    Config(String),
    /// Bad numeric input to a call.
    #[error(transparent)]
    Input(#[from] InputError),
    /// A problem with the automaton (e.g. an unknown state id).
    #[error(transparent)]
    Automaton(AutomatonError),
}

/// `bytes` in the largest binary unit that keeps it >= 1 (`"16.0 TiB"`).
fn human_bytes(bytes: usize) -> String {
    const UNITS: [&str; 7] = ["bytes", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} bytes")
    } else {
        format!("{value:.1} {}", UNITS[unit])
    }
}

/// The text of [`AutomatonError::NotReset`].
fn not_reset(row: &Option<usize>) -> String {
    match row {
        None => "the monitor has no episode yet: call reset(s0) before advance(s_next)".into(),
        Some(r) => format!("monitors row {r} has no episode yet: call reset(s0) on it first"),
    }
}

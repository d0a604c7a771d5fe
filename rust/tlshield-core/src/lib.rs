//! Pure-Rust core of **tlshield**: temporal-logic (scTLTL) specifications over state
//! predicates, their quantitative robustness over trajectories, and (in later modules) the
//! automaton, safe sets and the CLF-CBF quadratic program that shield a reinforcement-learning
//! agent.
//!
//! The crate knows nothing about Python; `tlshield-py` wraps it.
//!
//! ```
//! use tlshield_core::{Predicate, Spec, Trajectory};
//!
//! // "eventually s < 4" over a one-dimensional state.
//! let below_four = Predicate::halfspace(vec![-1.0], 4.0).unwrap();
//! let spec = Spec::new("F low", [("low", below_four)]).unwrap();
//! let states = [5.0, 4.5, 3.0, 6.0];
//! let rho = spec.robustness(Trajectory::new(&states, 1).unwrap()).unwrap();
//! assert_eq!(rho, 1.0); // max(4 - s_t) over the closed window s_0..s_3
//! ```

pub mod active_set;
pub mod alloc;
pub(crate) mod automaton;
pub mod channel;
pub(crate) mod check;
pub mod cnf;
pub mod custom;
pub(crate) mod dynamics;
pub(crate) mod error;
#[cfg(any(test, feature = "fixtures"))]
pub mod fixtures;
pub(crate) mod formula;
pub(crate) mod guidance;
pub(crate) mod linalg;
pub mod monitor;
pub(crate) mod parallel;
pub mod point_mass;
pub(crate) mod predicate;
pub mod progress;
pub mod qp;
pub(crate) mod region;
pub(crate) mod robustness;
/// The router's public names (the CLF's guidance around the discs the shield avoids), at the
/// path they have had since 0.3; they live in the crate's guidance room with the rest of the
/// CLF's guidance. See [`Router::target`](route::Router::target).
pub mod route {
    pub use crate::guidance::{
        Disc, Routed, Router, Routing, Scratch, Wall, DEFAULT_CLEARANCE, LOOKAHEAD, ROBOT_SLACK,
        SIDES, WORK_BOUND,
    };
}
pub(crate) mod sensitivity;
pub mod shield;
pub(crate) mod slots;
pub(crate) mod spec;
pub mod world;

pub use automaton::{Automaton, Edge, Reading, MAX_GUARD_CUBES, MAX_NODES, MAX_STATES};
pub use custom::CustomModel;
pub use dynamics::{Dynamics, Structure};
pub use error::{AutomatonError, InputError, ShieldError, SpecError};
pub use formula::Formula;
pub use monitor::{Monitor, MonitorBatch, MonitorState, TaskReward, TaskStep};
pub use predicate::{Ball, Center, Halfspace, Offset, Predicate};
pub use progress::{ProgressParams, ProgressReward};
pub use robustness::{Scratch, Trajectory, TrajectoryBatch};
pub use shield::{
    Barrier, BarrierSource, BatchDynamics, BatchGradient, BatchOutput, Bounds, ControlAffine,
    Filtered, Shield, ShieldParams, SolvedBy, SolverChoice, StateBatch, Status, Want,
};
pub use spec::Spec;

#[cfg(test)]
pub(crate) mod tests_support {
    use proptest::test_runner::{Config, RngSeed};

    /// Asserts that `r` is an error whose `Debug` form contains `kind` (the variant, e.g.
    /// `"Value"` or `"Input(Shape"`) and whose message contains `names` (the argument it
    /// names): an error test says which error and where, not just that there was one.
    #[track_caller]
    pub fn assert_error<T: std::fmt::Debug, E: std::fmt::Debug + std::fmt::Display>(
        r: Result<T, E>,
        kind: &str,
        names: &str,
    ) {
        match r {
            Ok(v) => panic!("expected a {kind} error naming {names:?}, got Ok({v:?})"),
            Err(e) => {
                let (debug, text) = (format!("{e:?}"), e.to_string());
                assert!(debug.contains(kind), "expected a {kind} error, got {debug}");
                assert!(
                    text.contains(names),
                    "expected the error to name {names:?}: {text}"
                );
            }
        }
    }

    /// Property-test settings with a fixed seed: the same cases on every run and machine.
    pub fn seeded(cases: u32) -> Config {
        Config {
            cases,
            rng_seed: RngSeed::Fixed(0x7115_4e1d),
            ..Config::default()
        }
    }
}

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
pub mod automaton;
pub mod channel;
pub mod cnf;
pub mod custom;
pub mod dynamics;
pub mod error;
#[cfg(any(test, feature = "fixtures"))]
pub mod fixtures;
pub mod formula;
pub mod linalg;
pub mod monitor;
pub mod parallel;
pub mod point_mass;
pub mod predicate;
pub mod progress;
pub mod qp;
pub mod region;
pub mod robustness;
pub mod sensitivity;
pub mod shield;
pub mod slots;
pub mod spec;
pub mod validate;
pub mod world;

pub use automaton::{Automaton, Edge, Reading};
pub use custom::CustomModel;
pub use dynamics::Dynamics;
pub use error::{AutomatonError, InputError, ShieldError, SpecError};
pub use formula::Formula;
pub use monitor::{Monitor, MonitorBatch, MonitorState, TaskReward, TaskStep};
pub use predicate::{Ball, Center, Halfspace, Predicate};
pub use progress::{ProgressParams, ProgressReward};
pub use robustness::{Scratch, Trajectory, TrajectoryBatch};
#[allow(deprecated)]
pub use shield::ShieldConfig;
pub use shield::{
    Barrier, BarrierSource, BatchDynamics, BatchGradient, BatchOutput, Bounds, ControlAffine,
    Filtered, Shield, ShieldParams, SolvedBy, SolverChoice, Status,
};
pub use spec::Spec;

#[cfg(test)]
pub(crate) mod tests_support {
    use proptest::test_runner::{Config, RngSeed};

    /// Property-test settings with a fixed seed: the same cases on every run and machine.
    pub fn seeded(cases: u32) -> Config {
        Config {
            cases,
            rng_seed: RngSeed::Fixed(0x7115_4e1d),
            ..Config::default()
        }
    }
}

//! Guidance (Eq. 5B1 and beyond the paper): where the shield's CLF leads the robot, in one
//! room. Read by the CLF row of Eq. 5D2 through one value, [`Aim`], and by the task monitor.
//!
//! - `goal.rs`: the CLF goal of Eq. 5B1, rank-aware: the deepest point of the most robust way
//!   a guard towards acceptance can hold;
//! - `plane.rs`: what the router sees of the predicates the shield avoids, discs in the plane
//!   of the CLF's position (one reading of a ball as geometry, `crate::region`'s `Round`);
//! - the router, a visibility-graph planner around those discs (`router.rs`, with its steps
//!   `inflate.rs`, `graph.rs`, `search.rs`; `reference.rs`, test only, the planner before its
//!   work was bounded, which it must agree with);
//! - `free.rs`: a goal partly covered by an avoided disc, aimed at at its free part;
//! - `reach.rs`: one routed step's decision (the target, whether its goal can be reached),
//!   and Eq. 5B1's choice restricted to goals that can;
//! - `aim.rs`: the point of the path the robot sees, the target the way left along it, and
//!   [`Aim`], what the CLF row reads (the target, the rows whose progress is uncredited, the
//!   turn towards the push).
//!
//! Guidance depends on the automaton (it reads a state's atoms) and on the geometry of
//! regions; nothing below it depends on guidance.

mod aim;
mod free;
mod goal;
mod graph;
mod inflate;
mod plane;
mod reach;
#[cfg(test)]
mod reference;
mod router;
mod search;

pub use aim::LOOKAHEAD;
pub(crate) use aim::{Aim, Manoeuvre, Turn};
pub(crate) use goal::GoalChoice;
pub use graph::{ROBOT_SLACK, SIDES};
pub use inflate::DEFAULT_CLEARANCE;
pub use plane::{Disc, Wall};
pub use reach::{Routed, Scratch};
pub use router::{Router, Routing};
pub use search::WORK_BOUND;

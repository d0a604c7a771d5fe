//! The discs as the planner sees them this step: each grown by the clearance, and shrunk where
//! it would hold the robot or the goal.

use super::graph::{norm, sub};
use super::router::Router;

/// The default inflation of each disc, relative to its radius.
pub const DEFAULT_CLEARANCE: f64 = 0.2;

/// How far inside the robot (or the goal) a disc that holds it is shrunk, relative to the
/// distance from its centre: a disc the robot has slipped into still leaves the robot outside
/// it, by a margin that rounding cannot close, so the robot is a node the graph can leave.
const KEEP_OUT: f64 = 1e-6;

impl Router {
    /// Whether a disc of this step holds `goal` (it cannot be reached: the router aims at it,
    /// and the barriers hold the robot).
    pub(super) fn holds(&self, goal: [f64; 2]) -> bool {
        self.discs
            .iter()
            .any(|d| norm(sub(goal, d.center)) < d.radius)
    }

    /// Per disc, the radius planned around this step: grown by `clearance` (relative to its
    /// radius), and shrunk to just exclude the robot at `p` and the goal when it holds them.
    pub(super) fn inflate(&mut self, p: [f64; 2], goal: [f64; 2], clearance: f64) {
        self.inflated.clear();
        for d in &self.discs {
            let keep = norm(sub(p, d.center)).min(norm(sub(goal, d.center))) * (1.0 - KEEP_OUT);
            self.inflated.push((d.radius * (1.0 + clearance)).min(keep));
        }
    }
}

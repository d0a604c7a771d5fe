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
            .any(|d| !far(sub(goal, d.center), d.radius) && norm(sub(goal, d.center)) < d.radius)
    }

    /// Per disc, the radius planned around this step: grown by `clearance` (relative to its
    /// radius), and shrunk to just exclude the robot at `p` and the goal when it holds them.
    pub(super) fn inflate(&mut self, p: [f64; 2], goal: [f64; 2], clearance: f64) {
        self.inflated.clear();
        for d in &self.discs {
            let grown = d.radius * (1.0 + clearance);
            let (to_p, to_goal) = (sub(p, d.center), sub(goal, d.center));
            if far(to_p, grown) && far(to_goal, grown) {
                // Both ends farther than the grown radius: `keep` below would exceed it.
                self.inflated.push(grown);
                continue;
            }
            let keep = norm(to_p).min(norm(to_goal)) * (1.0 - KEEP_OUT);
            self.inflated.push(grown.min(keep));
        }
    }
}

/// Whether `|v|` is surely more than twice `r`, by one of its components alone (`hypot` is at
/// least either): then the exact comparison (libm's `hypot`, which most of a step's discs
/// would otherwise pay for twice) is not needed. False for what it cannot tell (not a number).
#[inline]
fn far(v: [f64; 2], r: f64) -> bool {
    v[0].abs() > 2.0 * r || v[1].abs() > 2.0 * r
}

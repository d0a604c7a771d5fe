//! A goal partly covered by a disc the shield avoids (beyond the paper): the CLF aims at the
//! nearest point of the goal's free part instead of its deepest point, which the barrier would
//! hold the robot short of forever. Only a disc that stays put is looked past: one that moves
//! (a forklift, Channel-v0's obstacles) will uncover the goal, and chasing its rim would press
//! the robot against a moving barrier; the goal stays aimed at, and reported unreachable, while
//! it is covered.

use super::graph::{norm, sub};
use super::router::Router;

/// How far outside a covering disc a free point lies, relative to its radius: enough that the
/// barrier, which holds the robot on the rim at best, lets it reach the point.
const RIM_MARGIN: f64 = 0.05;

/// The directions tried around each covering disc, from the one through the goal outwards on
/// both sides: steps of `PI / STEPS` up to a half-turn.
const STEPS: usize = 12;

impl Router {
    /// The point nearest `goal` (at least a [`RIM_MARGIN`] outside every disc of this step)
    /// that `in_goal` accepts, among those just outside each disc that stays put and holds the
    /// goal, in
    /// directions fanned out from the one through the goal (or towards the robot at `p`, for a
    /// goal at a disc's centre). `None` when no such point is in the goal: the goal is covered.
    pub(super) fn free_part(
        &self,
        p: [f64; 2],
        goal: [f64; 2],
        in_goal: &mut dyn FnMut([f64; 2]) -> bool,
    ) -> Option<[f64; 2]> {
        let mut best: Option<([f64; 2], f64)> = None;
        for (d, _) in self
            .discs
            .iter()
            .zip(&self.still)
            .filter(|(_, &still)| still)
        {
            let out = sub(goal, d.center);
            if norm(out) >= d.radius {
                continue;
            }
            let base = if norm(out) > 0.0 {
                out
            } else {
                sub(p, d.center)
            };
            let start = base[1].atan2(base[0]);
            for k in 0..=2 * STEPS {
                // 0, +1, -1, +2, -2, ... steps from the direction through the goal.
                let step = (k as f64 / 2.0).ceil() * if k % 2 == 1 { 1.0 } else { -1.0 };
                let (sin, cos) = (start + step * std::f64::consts::PI / STEPS as f64).sin_cos();
                let reach = d.radius * (1.0 + RIM_MARGIN);
                let point = [d.center[0] + reach * cos, d.center[1] + reach * sin];
                let far = norm(sub(point, goal));
                if best.is_some_and(|(_, b)| b <= far) || self.near_any(point) || !in_goal(point) {
                    continue;
                }
                best = Some((point, far));
            }
        }
        best.map(|(point, _)| point)
    }

    /// Whether `point` lies within [`RIM_MARGIN`] of a disc of this step (or inside it).
    fn near_any(&self, point: [f64; 2]) -> bool {
        self.discs
            .iter()
            .any(|d| norm(sub(point, d.center)) < d.radius * (1.0 + RIM_MARGIN) * (1.0 - 1e-9))
    }
}

#[cfg(test)]
mod tests {
    use super::super::router::tests::router;
    use super::*;

    #[test]
    fn a_goal_whose_centre_a_shelf_covers_is_aimed_at_its_free_edge() {
        // The goal: a disc of radius 0.3 at the origin; the shelf, radius 0.25 at (0.1, 0).
        let r = router(&[([0.1, 0.0], 0.25)]);
        let mut in_goal = |q: [f64; 2]| norm(q) < 0.3;
        let free = r.free_part([-3.0, 0.0], [0.0, 0.0], &mut in_goal).unwrap();
        assert!(norm(free) < 0.3, "{free:?}");
        assert!(norm(sub(free, [0.1, 0.0])) >= 0.25 * (1.0 + RIM_MARGIN) - 1e-12);
        // Straight out from the shelf's centre through the goal's: the side facing the robot.
        assert!(free[0] < 0.0 && free[1].abs() < 1e-9, "{free:?}");
    }

    #[test]
    fn a_goal_a_shelf_covers_whole_has_no_free_part() {
        let r = router(&[([0.0, 0.0], 0.5)]);
        let mut in_goal = |q: [f64; 2]| norm(q) < 0.3;
        assert_eq!(r.free_part([-3.0, 0.0], [0.0, 0.0], &mut in_goal), None);
    }

    #[test]
    fn a_free_point_inside_another_disc_is_passed_over() {
        // Two shelves: the direction through the goal ends in the second one.
        let r = router(&[([0.1, 0.0], 0.25), ([-0.3, 0.0], 0.12)]);
        let mut in_goal = |q: [f64; 2]| norm(q) < 0.35;
        let free = r.free_part([-3.0, 0.0], [0.0, 0.0], &mut in_goal).unwrap();
        assert!(norm(free) < 0.35 && !r.near_any(free), "{free:?}");
    }
}

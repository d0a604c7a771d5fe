//! Where the CLF aims: the point of the router's path that the robot sees, the target placed
//! the way left along it, and [`Aim`], the one value the CLF row of Eq. 5D2 reads (the target,
//! whether guidance changed the row, the rows whose progress it uncredits, the turn term, the
//! RL action's turn the CLF may cancel).
//!
//! The router's target replaces the goal of Eq. 5B1 when the straight line is blocked; the
//! barrier rows the router goes around then must not credit progress into them, a robot that
//! must turn is asked to turn towards the push, and an RL action's turn into a disc the CBF
//! blocks does not hold the CLF's turn (all beyond the paper, see the methods).

use super::graph::{norm, past_tangent, sub, Node};
use super::plane::{each_disc, is_disc, Disc};
use super::reach::{Routed, Scratch};
use super::router::{Router, Routing};
use crate::automaton::Reading;
use crate::cnf::Literal;
use crate::linalg::dot;
use crate::predicate::Predicate;

/// The aim's distance along the path, in inflated radii of the disc the path meets first.
pub const LOOKAHEAD: f64 = 1.0;
/// How much nearer each retry of the aim looks along the path when the point a lookahead along
/// it is out of sight: a geometric back-off reaches the path's first node in a few tries.
const BACK_OFF: f64 = 0.8;
/// An aim this close to the robot has no direction to stretch the target along: the aim
/// itself is the target.
const AT_ROBOT: f64 = 1e-12;
/// A CLF value at or below this: the robot is at its target and the push has no direction to
/// turn towards (the angle of a zero error is meaningless).
const NO_PUSH: f64 = 1e-18;

/// Backing out of its turning circle, a car asks at least this share of the position's error
/// as speed ([`Aim::move_to_turn`]): the target may lie nearly ahead, where the angle alone
/// would ask almost none.
const BACK_OUT: f64 = 0.25;
/// A car whose target has left its turning circle drives forwards again only once the
/// target is this many radii from the circle's centre; in between it keeps the way it moves
/// ([`Manoeuvre::way`]), so that it does not rock on the circle's rim.
const CLEAR_OF_CIRCLE: f64 = 1.5;
/// A car whose nose is this close to the rim of a disc it heads into (a share of the disc's
/// radius) backs out ([`Aim::backs_out`]): forwards, the barrier holds it there, and at rest it
/// cannot turn.
const NOSE: f64 = 0.1;

/// What [`Aim::move_to_turn`] reads of a car at one step: its heading, its speed, and the
/// radius of the tightest circle the CLF's own steering drives at that speed (`None` at rest,
/// where no turn can be made).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Manoeuvre {
    /// The heading.
    pub(crate) theta: f64,
    /// The signed speed along the heading.
    pub(crate) speed: f64,
    /// The tightest turning circle's radius at this speed.
    pub(crate) radius: Option<f64>,
}

impl Manoeuvre {
    /// The way to drive (`+1` forwards, `-1` backwards) towards `target` from `p`, and whether
    /// the car is backing out of its turning circle: backwards while the target is behind the
    /// axle line (`cos off < 0`; backing up turns the car towards it) or inside the turning
    /// circle on its side (driving forwards would only circle it); forwards once it is
    /// [`CLEAR_OF_CIRCLE`] radii from that circle's centre; in between, the way it moves.
    fn way(&self, off: f64, p: [f64; 2], target: [f64; 2]) -> (f64, bool) {
        if off.cos() < 0.0 {
            return (-1.0, false);
        }
        let Some((centre, radius)) = self.circle(p, target) else {
            return (1.0, false);
        };
        let from_centre = norm(sub(target, centre));
        if from_centre < radius {
            (-1.0, true)
        } else if from_centre > CLEAR_OF_CIRCLE * radius || self.speed >= 0.0 {
            (1.0, false)
        } else {
            (-1.0, true)
        }
    }

    /// The tightest circle the car drives at this speed on the side of `target` (centre,
    /// radius), `None` at rest.
    fn circle(&self, p: [f64; 2], target: [f64; 2]) -> Option<([f64; 2], f64)> {
        let radius = self.radius?;
        let (sin, cos) = self.theta.sin_cos();
        let to = sub(target, p);
        let side = if cos * to[1] - sin * to[0] >= 0.0 {
            1.0
        } else {
            -1.0
        };
        Some((
            [p[0] - side * radius * sin, p[1] + side * radius * cos],
            radius,
        ))
    }
}

/// The distance along the path at which the router aims past a disc of `radius`, grown by
/// `clearance`: [`LOOKAHEAD`] inflated radii.
pub(super) fn lookahead(radius: f64, clearance: f64) -> f64 {
    LOOKAHEAD * radius * (1.0 + clearance)
}

impl Router {
    /// The target after a search that reached the goal, for a robot at `p`: in the direction
    /// of [`Router::aim`], as far away as the path is long, so that `V = |p - target|^2` is the
    /// squared length of the way left (a CLF whose gradient points along the path, and which
    /// asks the speed it would ask of a clear goal).
    pub(super) fn place_target(&self, p: [f64; 2], clearance: f64) -> [f64; 2] {
        let aim = self.aim(p, clearance);
        let u = sub(aim, p);
        let len = norm(u);
        if len <= AT_ROBOT {
            return aim;
        }
        let left = self.way_to(Node::Goal);
        [p[0] + left * u[0] / len, p[1] + left * u[1] / len]
    }

    /// A point of the last path found that the robot at `p` sees (see the router's docs): the
    /// point a lookahead along the path, or, hidden behind the disc the path wraps around, the
    /// way along the tangent on its side; else the farthest point short of it in sight; the
    /// first node at the least, which the robot sees by construction.
    pub(super) fn aim(&self, p: [f64; 2], clearance: f64) -> [f64; 2] {
        let mut first = Node::Goal;
        while self.before(first) != Node::Robot {
            first = self.before(first);
        }
        let corner_at = self.point(first);
        let Node::Corner(k) = first else {
            return corner_at;
        };
        let disc = self.corners[k].disc;
        let lookahead = lookahead(self.discs[disc].radius, clearance);
        let carrot = self.along_path(lookahead);
        if self.visible_from_robot(p, carrot) {
            return carrot;
        }
        // Hidden behind the disc the path wraps around (the robot on its rim): the way along
        // the tangent from the robot on the carrot's side, which it sees.
        let (c, r) = (self.discs[disc].center, self.inflated[disc]);
        let [a, b] = [1.0, -1.0].map(|side| past_tangent(p, c, r, side, lookahead));
        let toward = if norm(sub(a, carrot)) <= norm(sub(b, carrot)) {
            a
        } else {
            b
        };
        if self.visible_from_robot(p, toward) {
            return toward;
        }
        let mut along = BACK_OFF * lookahead;
        while along > self.way_to(first) {
            let carrot = self.along_path(along);
            if self.visible_from_robot(p, carrot) {
                return carrot;
            }
            along *= BACK_OFF;
        }
        corner_at
    }

    /// The point at length `along` on the last path found (robot to goal; the goal past its
    /// end).
    fn along_path(&self, along: f64) -> [f64; 2] {
        let mut node = Node::Goal;
        while self.before(node) != Node::Robot && self.way_to(self.before(node)) >= along {
            node = self.before(node);
        }
        if self.way_to(node) <= along {
            return self.point(node);
        }
        let before = self.before(node);
        let (a, b) = (self.point(before), self.point(node));
        let t = (along - self.way_to(before)) / (self.way_to(node) - self.way_to(before));
        [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
    }
}

/// The RL action's turn the CLF may cancel on one input, `released` ([`Aim::release_blocked_turn`]),
/// widens that input's CLF box `(lo, hi)` on the side that cancels it: the CLF keeps its own box
/// beyond the RL action's turn.
fn widened(lo: f64, hi: f64, released: f64) -> (f64, f64) {
    (lo - released.max(0.0), hi - released.min(0.0))
}

/// What the turn towards the push adds to the CLF ([`Aim::turn_towards_push`]): to `V` and to
/// `Lf V` (its `Lg V` part is added in place).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Turn {
    /// Added to `V`.
    pub(crate) v: f64,
    /// Added to `Lf V`.
    pub(crate) lf: f64,
}

/// Where the CLF of one step aims and what guidance changed in its row: the one value the CLF
/// row of Eq. 5D2 reads from guidance. It owns its buffers (the target, the per-row flags, the
/// planner's), reused from step to step: allocation-free once grown.
#[derive(Debug, Default)]
pub(crate) struct Aim {
    /// The CLF's target: the goal of Eq. 5B1, or the router's target in its place (as far from
    /// the robot as the way left is long).
    pub(crate) target: Vec<f64>,
    /// Whether guidance changed this step's CLF row: a target other than the goal, progress
    /// uncredited ([`Aim::uncredit_blocked_progress`]), a turn asked
    /// ([`Aim::turn_towards_push`]) or the RL action's turn released
    /// ([`Aim::release_blocked_turn`]).
    rerouted: bool,
    /// Per barrier row: whether the router goes around it (the outside of a disc over the
    /// CLF's position), so that progress into it may be uncredited.
    routed: Vec<bool>,
    /// Per barrier row: `-dh/dp` over the CLF's two position dimensions (the direction into
    /// the disc, for a routed row; zero for the others).
    inward: Vec<[f64; 2]>,
    /// Per barrier row: whether it is a routed disc that stays put (its predicate reads only
    /// the position), the only kind whose blocking turn is released to the CLF.
    still: Vec<bool>,
    /// Per barrier row that is a routed disc staying put: its disc nearest the state (a car
    /// backs away from it, [`Aim::backs_out`]).
    nearest: Vec<Option<Disc>>,
    /// Per input: the part of the RL action the CLF's box is widened to cancel this step (the
    /// RL action's turn into a blocked disc, [`Aim::release_blocked_turn`]); zero elsewhere.
    released: Vec<f64>,
    /// The planner's buffers.
    router: Router,
    /// The safe set routed around, when the barrier rows did not read it.
    safe: Vec<(Literal, f64)>,
    /// Whether this step's goal cannot be reached from the state ([`Aim::goal_unreachable`]).
    unreachable: bool,
    /// The routed choice's scratch.
    scratch: Scratch,
}

impl Aim {
    /// Starts a step: no barrier row noted yet, nothing changed.
    pub(crate) fn start(&mut self) {
        self.routed.clear();
        self.inward.clear();
        self.still.clear();
        self.nearest.clear();
        self.released.clear();
        self.rerouted = false;
        self.unreachable = false;
    }

    /// Whether this step's goal (Eq. 5B1's) cannot be reached from the state, as far as the
    /// router can tell: the goal lies where the shield does not let the robot be (inside a disc
    /// it avoids, or outside a region a kept literal or a user barrier holds it in, read with
    /// the CLF's position at the goal and every other dimension as it is), or no way around
    /// the discs leads to it. The CLF then aims at the goal anyway and the barriers hold the
    /// robot short of it: a parked robot, which this names.
    pub(crate) fn goal_unreachable(&self) -> bool {
        self.unreachable
    }

    /// Whether guidance changed this step's CLF row.
    pub(crate) fn rerouted(&self) -> bool {
        self.rerouted
    }

    /// Notes the next barrier row, on `predicate` signed by `sign` (`h = sign rho`): the
    /// router goes around it when it keeps the state outside a disc over the two dimensions
    /// `pos` at `s`. `grad` is the row's `dh/ds` at `s` (`sign` applied), whose position part
    /// points out of the disc.
    pub(crate) fn note_row(
        &mut self,
        (predicate, sign): (&Predicate, f64),
        pos: &[usize],
        s: &[f64],
        grad: &[f64],
    ) {
        let routed = sign < 0.0 && pos.len() == 2 && is_disc(predicate, pos, s);
        self.routed.push(routed);
        // A disc read from other dimensions than the position moves (or turns with the body):
        // its barrier, not the CLF, answers a turn towards it.
        let moves = || (0..s.len()).any(|d| !pos.contains(&d) && predicate.reads(d));
        let still = routed && !moves();
        self.still.push(still);
        let mut nearest: Option<Disc> = None;
        if still {
            let p = [s[pos[0]], s[pos[1]]];
            let gap = |d: &Disc| norm(sub(d.center, p)) - d.radius;
            each_disc(predicate, pos, s, &mut |d| {
                if nearest.as_ref().is_none_or(|n| gap(&d) < gap(n)) {
                    nearest = Some(d);
                }
            });
        }
        self.nearest.push(nearest);
        self.inward.push(match routed {
            true => [-grad[pos[0]], -grad[pos[1]]],
            false => [0.0, 0.0],
        });
    }

    /// Notes the next barrier row as one the router does not go around.
    pub(crate) fn note_unrouted_row(&mut self) {
        self.routed.push(false);
        self.still.push(false);
        self.nearest.push(None);
        self.inward.push([0.0, 0.0]);
    }

    /// Replaces the goal by the router's target around the discs this step keeps the state out
    /// of: `routing`'s user barriers and the avoided literals of its safe set at `(reading, q)`
    /// that are the outside of a ball (or of a union of balls) over the CLF's position.
    /// `planned`: the target a task monitor routed the same way has planned at this state
    /// already; `safe`: the safe set when the barrier rows have read it (else it is read here).
    pub(crate) fn route(
        &mut self,
        routing: &Routing,
        planned: Option<Routed>,
        reading: &Reading<'_>,
        q: usize,
        safe: Option<&[(Literal, f64)]>,
    ) {
        let routed = match planned {
            Some(routed) => routed,
            None => {
                let safe = match safe {
                    Some(safe) => safe,
                    None => {
                        routing.safe_set(reading, q, &mut self.safe);
                        &self.safe
                    }
                };
                let goal = [self.target[0], self.target[1]];
                let buffers = (&mut self.router, &mut self.scratch);
                routing.route(reading, q, goal, safe, buffers)
            }
        };
        self.unreachable = routed.unreachable;
        self.aim_at(routed.target);
    }

    /// Puts the router's `target` in place of the goal.
    fn aim_at(&mut self, target: [f64; 2]) {
        self.rerouted |= target != [self.target[0], self.target[1]];
        self.target.copy_from_slice(&target);
    }

    /// Progress the barriers will cancel is not progress: for every row of a barrier the router
    /// goes around (the outside of a disc) that the RL action alone violates
    /// (`r + L . a_rl < 0`, so the CBF will cut that action), the part of `Lg V` (`lg_v`) that
    /// credits motion into the barrier (`Lg V . L > 0`) is projected out. `lg` holds each
    /// barrier row's `L` (as many values as `lg_v`) and `rhs` its `r + L . a_rl`. Without
    /// this, a push into an obstacle that also points towards the target satisfies the CLF row
    /// while `a_cbf` cancels it: a parked equilibrium with `delta = 0` (measured with a greedy
    /// seeker on the unicycle). With it, the CLF must find its decrease along the barrier.
    pub(crate) fn uncredit_blocked_progress(&mut self, lg_v: &mut [f64], lg: &[f64], rhs: &[f64]) {
        let rows = lg.chunks_exact(lg_v.len()).zip(rhs).zip(&self.routed);
        for ((row, &rhs), &routed) in rows {
            if rhs >= 0.0 || !routed {
                continue;
            }
            let (along, norm2) = (dot(lg_v, row), dot(row, row));
            if along > 0.0 && norm2 > 0.0 {
                let t = along / norm2;
                for (l, r) in lg_v.iter_mut().zip(row) {
                    *l -= t * r;
                }
                self.rerouted = true;
            }
        }
    }

    /// The RL action's turn into a blocked disc does not hold the CLF's turn. For a robot that
    /// turns (its heading `theta`, with `g_theta` the heading's row of `g`): for every disc the
    /// router goes around that blocks the RL action (the RL action alone violates its row, `rhs`
    /// holding each barrier row's `r + L . a_rl`, so the CBF will cut that action; or the
    /// heading points into the disc), every input of `a_rl` that turns the heading towards that
    /// disc (it grows the heading's component into the disc) is released: the CLF's box on that input is widened so that `a_clf` can cancel it
    /// ([`widened`], read by [`Aim::clf_box`]), beside its own box. Without this, a policy
    /// that steers at its goal behind a disc holds the heading into the disc as hard as the
    /// CLF's box turns it away, and `a_cbf` cancels the forward push: a parked equilibrium
    /// (measured with greedy seekers at a CLF box of half the limits). The barrier rows are
    /// untouched, and the CLF's cost `|a_clf|^2` still prices the cancelled turn, so a turn the
    /// CLF's decrease does not need is kept.
    pub(crate) fn release_blocked_turn(
        &mut self,
        theta: f64,
        g_theta: &[f64],
        a_rl: &[f64],
        rhs: &[f64],
    ) {
        self.released.clear();
        self.released.resize(a_rl.len(), 0.0);
        // d(heading . inward)/d(theta): positive when turning up the angle points the
        // heading further into the disc.
        let (sin, cos) = theta.sin_cos();
        let blocked = rhs.iter().zip(&self.still).zip(&self.inward);
        for ((&rhs, &routed), inward) in blocked {
            // Blocked: the CBF will cut the RL action (its row is violated), or the heading
            // points into the disc (a policy that turned past it pushes no more, but its turn
            // still holds the heading there).
            let ahead = cos * inward[0] + sin * inward[1];
            if !routed || (rhs >= 0.0 && ahead <= 0.0) {
                continue;
            }
            let into = -sin * inward[0] + cos * inward[1];
            let parts = self.released.iter_mut().zip(g_theta).zip(a_rl);
            for ((released, &g), &a) in parts {
                if g * a * into > 0.0 {
                    *released = a;
                    self.rerouted = true;
                }
            }
        }
    }

    /// A car's throttle into a disc at its nose does not hold it there either (nor backwards
    /// into one at its tail): for a car at `p` heading `theta`, at the rim of a routed disc
    /// that stays put ([`Aim::at_rim`]), every input of `a_rl` that pushes its speed (`g_v`,
    /// the speed's row of `g`) towards that disc is released to the CLF, as
    /// [`Aim::release_blocked_turn`] releases a turn. Without this, a policy that drives at its
    /// goal behind a disc holds the car's nose at the rim, where it cannot turn, as hard as
    /// the CLF's box backs it out. Call after [`Aim::release_blocked_turn`].
    pub(crate) fn release_blocked_throttle(
        &mut self,
        (theta, p): (f64, [f64; 2]),
        g_v: &[f64],
        a_rl: &[f64],
    ) {
        let ahead = self.at_rim(theta, p, 1.0);
        let behind = self.at_rim(theta, p, -1.0);
        if !(ahead || behind) {
            return;
        }
        self.released.resize(a_rl.len(), 0.0);
        let parts = self.released.iter_mut().zip(g_v).zip(a_rl);
        for ((released, &g), &a) in parts {
            if (ahead && g * a > 0.0) || (behind && g * a < 0.0) {
                *released = a;
                self.rerouted = true;
            }
        }
    }

    /// The CLF's box this step on input `j`: `bounds` (its `(lo, hi)`) widened by the RL
    /// action's turn released on `j` ([`Aim::release_blocked_turn`]).
    pub(crate) fn clf_box(&self, (lo, hi): (f64, f64), j: usize) -> (f64, f64) {
        widened(lo, hi, self.released.get(j).copied().unwrap_or(0.0))
    }

    /// The RL action's part released on input `j` (zero when none): the CLF box's widened side
    /// moves with `a_rl_j` by `-1` (the gradient reads it).
    pub(crate) fn released(&self, j: usize) -> f64 {
        self.released.get(j).copied().unwrap_or(0.0)
    }

    /// Robots that must turn (beyond the paper): under a model whose turn input reaches the
    /// position only through the heading (`Dynamics::steered_heading`), the second-order CLF's
    /// `Lg V` has no part on the turn, so the QP brakes where it should turn. The CLF gains
    /// `lambda (1 - cos(theta - psi))`, with `psi` the direction the CLF pushes (`-e`, `e` the
    /// CLF's error at the two position dimensions) and `lambda = |e|^2 = v`, both held for the
    /// step: its decrease asks the heading `theta` to turn towards the push. `g_theta` and
    /// `f_theta` are the heading's rows of `g` and `f`; `lg_v` is `Lg V`, updated in place.
    pub(crate) fn turn_towards_push(
        &mut self,
        e: [f64; 2],
        theta: f64,
        (g_theta, f_theta): (&[f64], f64),
        v: f64,
        lg_v: &mut [f64],
    ) -> Turn {
        let [ex, ey] = e;
        if v <= NO_PUSH {
            return Turn { v: 0.0, lf: 0.0 };
        }
        let off = theta - (-ey).atan2(-ex);
        let (sin, cos) = off.sin_cos();
        for (l, g) in lg_v.iter_mut().zip(g_theta) {
            *l += v * sin * g;
        }
        self.rerouted = true;
        Turn {
            v: v * (1.0 - cos),
            lf: v * sin * f_theta,
        }
    }

    /// Whether a car at `p` backs away from a routed disc that stays put and lies ahead of it
    /// (towards `target`, which is not behind its axle line): its nose is within [`NOSE`] of
    /// the disc's radius from the rim, where forwards the barrier holds it and at rest it
    /// cannot turn; or, backing already, with the disc's rim within the car's turning radius,
    /// its tightest forward circle on the target's side still crosses that disc, so that
    /// driving on would take it back to the rim.
    fn backs_out(&self, car: Manoeuvre, p: [f64; 2], target: [f64; 2]) -> bool {
        let (sin, cos) = car.theta.sin_cos();
        let circle = match car.speed < 0.0 {
            true => car.circle(p, target),
            false => None,
        };
        self.at_rim(car.theta, p, 1.0)
            || self.nearest.iter().flatten().any(|d| {
                let to = sub(d.center, p);
                let ahead = cos * to[0] + sin * to[1] > 0.0;
                // Only a disc within a turning radius of the car is one it backs away from.
                ahead
                    && circle.is_some_and(|(c, radius)| {
                        norm(to) - d.radius <= radius
                            && (norm(sub(d.center, c)) - radius).abs() < d.radius
                    })
            })
    }

    /// Whether a car at `p` heading `theta` is within [`NOSE`] of a routed still disc's
    /// radius from its rim, the disc ahead (`way = 1`) or behind (`way = -1`).
    fn at_rim(&self, theta: f64, p: [f64; 2], way: f64) -> bool {
        let (sin, cos) = theta.sin_cos();
        self.nearest.iter().flatten().any(|d| {
            let to = sub(d.center, p);
            way * (cos * to[0] + sin * to[1]) > 0.0 && norm(to) - d.radius <= NOSE * d.radius
        })
    }

    /// Robots that turn only while moving (beyond the paper), a car: its turn rate is `v tan
    /// delta / l`, so at rest the turn term's `Lg V` on the steering is zero
    /// ([`Aim::turn_towards_push`]), and with its target abeam the push along the heading is
    /// zero too: the car parks. The CLF gains `(v* - sigma v)_+^2`, the speed the manoeuvre
    /// needs not yet reached, never a brake: `v* = |d| sin^2(off / 2)`, with `d = k (p -
    /// target)` (the position's part of the CLF's error, a speed; `p` the CLF's position) and
    /// `off` the heading's angle from the target's bearing, both read at the position only
    /// and held for the step. `sigma` is the way to drive ([`Manoeuvre::way`]); backing up,
    /// the manoeuvre owns the speed: the position's push along the heading would drive the
    /// car on, into the circle it cannot leave forwards, so its part on the speed's inputs
    /// gives way, and `v*` is at least [`BACK_OUT`] of `|d|`. `speed` is the speed's state
    /// value and `(g_v, f_v)` its rows of `g` and `f`; `lg_v` is `Lg V`, updated in place.
    pub(crate) fn move_to_turn(
        &mut self,
        (d, p): ([f64; 2], [f64; 2]),
        car: Manoeuvre,
        (g_v, f_v): (&[f64], f64),
        lg_v: &mut [f64],
    ) -> Turn {
        let [dx, dy] = d;
        if dx * dx + dy * dy <= NO_PUSH {
            return Turn { v: 0.0, lf: 0.0 };
        }
        let off = car.theta - (-dy).atan2(-dx);
        let target = [self.target[0], self.target[1]];
        let (sigma, circled) = match off.cos() >= 0.0 && self.backs_out(car, p, target) {
            true => (-1.0, true),
            false => car.way(off, p, target),
        };
        // Backing with its tail at a disc's rim, the car drives on instead: the barrier holds
        // it there too.
        let (sigma, circled) = match sigma < 0.0 && self.at_rim(car.theta, p, -1.0) {
            true => (1.0, false),
            false => (sigma, circled),
        };
        let share = (0.5 * off).sin().powi(2);
        let share = if circled { share.max(BACK_OUT) } else { share };
        let short = dx.hypot(dy) * share - sigma * car.speed;
        if short <= 0.0 {
            return Turn { v: 0.0, lf: 0.0 };
        }
        // d/dt (v* - sigma v)^2 = -2 sigma (v* - sigma v) (f_v + g_v . a), v* held.
        for (l, g) in lg_v.iter_mut().zip(g_v) {
            if sigma < 0.0 && *g != 0.0 {
                *l = 0.0;
            }
            *l -= 2.0 * sigma * short * g;
        }
        self.rerouted = true;
        Turn {
            v: short * short,
            lf: -2.0 * sigma * short * f_v,
        }
    }
}

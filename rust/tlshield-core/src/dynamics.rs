//! Control-affine dynamics `ds/dt = f(s) + g(s) a` for the shield: a single integrator, the
//! unicycle reference point of the paper (Eq. 6A2), three acceleration-level models (a double
//! integrator, a unicycle driven by acceleration and turn rate, and a kinematic bicycle driven
//! by acceleration and the tangent of its steering angle), or a user's own model whose values
//! come with every call (`custom.rs`). Each built-in model also gives exact products with the
//! Jacobian of `f`, which the second-order (HOCBF) rows and the second-order CLF need.

use crate::check::check_finite;
use crate::error::InputError;

/// A built-in control-affine model over a state of length `n` with `m` inputs.
#[derive(Debug, Clone, PartialEq)]
pub enum Dynamics {
    /// `ds[pos[i]]/dt = a[i]`; every other state value has zero drift and no input.
    SingleIntegrator {
        /// The state dimensions driven by the inputs (m = pos.len()).
        pos: Vec<usize>,
    },
    /// The unicycle's reference point `eps` ahead of its centre (paper Eq. 6A2):
    /// `[dx, dy] = R(theta) diag(1, eps) [a_v, a_theta]`, `dtheta = a_theta`; m = 2.
    Unicycle {
        /// Distance of the reference point ahead of the centre (> 0).
        eps: f64,
        /// State index of the reference point's x.
        x: usize,
        /// State index of the reference point's y.
        y: usize,
        /// State index of the heading.
        theta: usize,
    },
    /// `ds[pos[i]]/dt = s[vel[i]]`, `ds[vel[i]]/dt = a[i]`: m = pos.len() accelerations. A
    /// barrier on positions has relative degree 2 under it.
    DoubleIntegrator {
        /// The position dimensions.
        pos: Vec<usize>,
        /// The velocity dimension of each position (same length).
        vel: Vec<usize>,
    },
    /// A unicycle driven at acceleration level: `dx = v cos theta`, `dy = v sin theta`,
    /// `dtheta = a[1]` (turn rate), `dv = a[0]` (forward acceleration); m = 2. A barrier on
    /// `x, y` has relative degree 2 under it.
    AccelerationUnicycle {
        /// State index of x.
        x: usize,
        /// State index of y.
        y: usize,
        /// State index of the heading.
        theta: usize,
        /// State index of the forward speed.
        v: usize,
    },
    /// A kinematic bicycle about its rear axle, wheelbase `l`: `dx = v cos theta`,
    /// `dy = v sin theta`, `dtheta = v a[1] / l`, `dv = a[0]`, with inputs (acceleration,
    /// `tan delta`) for steering angle `delta`. Taking `tan delta` as the input keeps the model
    /// control-affine and exact, and turns the steering limit into a constant box
    /// `|a[1]| <= tan(delta_max)`: the turn rate it allows, `|v| tan(delta_max) / l`, shrinks
    /// with speed by the model itself. A barrier on `x, y` has relative degree 2 under it.
    KinematicBicycle {
        /// Wheelbase (distance between the axles, > 0).
        l: f64,
        /// State index of the rear axle's x.
        x: usize,
        /// State index of the rear axle's y.
        y: usize,
        /// State index of the heading.
        theta: usize,
        /// State index of the forward speed.
        v: usize,
    },
    /// A body pushed along its heading, turned at a commanded rate and slowed by linear drag,
    /// with its velocity a state of its own (not tied to the heading): `dx = vx`, `dy = vy`,
    /// `dtheta = turn a[1]`, `dvx = thrust a[0] cos theta - drag vx`,
    /// `dvy = thrust a[0] sin theta - drag vy`; m = 2. Safety-Gymnasium's Point robot is this
    /// model, identified from MuJoCo (`tlshield.envs.safety_gym`). A barrier on `x, y` has
    /// relative degree 2, acted on by the thrust alone: it loses authority while the heading
    /// is perpendicular to the barrier's gradient (the drag then slows the body). With
    /// `alpha <= drag <= alpha + alpha2` the drag alone keeps the sampled second-order row
    /// among still obstacles, so zero thrust is always admissible there.
    ThrustTurn {
        /// Acceleration per unit of `a[0]` (m/s^2, > 0).
        thrust: f64,
        /// Turn rate per unit of `a[1]` (rad/s, > 0).
        turn: f64,
        /// Linear drag (1/s, >= 0).
        drag: f64,
        /// State index of x.
        x: usize,
        /// State index of y.
        y: usize,
        /// State index of the heading.
        theta: usize,
        /// State index of the x velocity.
        vx: usize,
        /// State index of the y velocity.
        vy: usize,
    },
}

/// What the relative-degree analysis (`shield/order.rs`) reads of a model: which state
/// dimensions an input moves directly, and which through one integration.
pub trait Structure: std::fmt::Display {
    /// Whether an input can move state dimension `d` directly (row `d` of `g` may be
    /// non-zero).
    fn actuates(&self, d: usize) -> bool;
    /// Whether an input moves state dimension `d` through one integration (`f[d]` depends on
    /// an actuated dimension).
    fn actuates_twice_removed(&self, d: usize) -> bool;
    /// The dimensions of the model's position (what a CLF drives to a goal), if it has one.
    fn position(&self) -> Option<Vec<usize>> {
        None
    }
    /// Whether an input moves state dimension `d` at all (directly or through one
    /// integration).
    fn moves(&self, d: usize) -> bool {
        self.actuates(d) || self.actuates_twice_removed(d)
    }
}

impl Structure for Dynamics {
    fn actuates(&self, d: usize) -> bool {
        Dynamics::actuates(self, d)
    }

    fn actuates_twice_removed(&self, d: usize) -> bool {
        Dynamics::actuates_twice_removed(self, d)
    }

    fn position(&self) -> Option<Vec<usize>> {
        Some(match self {
            Dynamics::SingleIntegrator { pos } | Dynamics::DoubleIntegrator { pos, .. } => {
                pos.clone()
            }
            Dynamics::Unicycle { x, y, .. }
            | Dynamics::AccelerationUnicycle { x, y, .. }
            | Dynamics::KinematicBicycle { x, y, .. }
            | Dynamics::ThrustTurn { x, y, .. } => vec![*x, *y],
        })
    }
}

fn distinct(what: &str, dims: &[usize]) -> Result<(), InputError> {
    if (1..dims.len()).any(|i| dims[..i].contains(&dims[i])) {
        return Err(InputError::Shape {
            what: what.into(),
            expected: "distinct state dimensions".into(),
            got: format!("{dims:?}"),
        });
    }
    Ok(())
}

/// Checks an Euler step's action (`m` finite values) and time step (finite, > 0).
pub(crate) fn check_step_input(a: &[f64], m: usize, dt: f64) -> Result<(), InputError> {
    if a.len() != m {
        return Err(InputError::Shape {
            what: "a".into(),
            expected: format!("{m} values (one per input)"),
            got: a.len().to_string(),
        });
    }
    check_finite("a", a, a.len())?;
    if !(dt.is_finite() && dt > 0.0) {
        return Err(InputError::Value {
            what: "dt".into(),
            expected: "a finite time step > 0".into(),
            got: dt.to_string(),
        });
    }
    Ok(())
}

impl Dynamics {
    /// A single integrator on `pos` (non-empty, distinct dimensions).
    pub fn single_integrator(pos: Vec<usize>) -> Result<Self, InputError> {
        if pos.is_empty() || (1..pos.len()).any(|i| pos[..i].contains(&pos[i])) {
            return Err(InputError::Value {
                what: "SingleIntegrator pos".into(),
                expected: "at least one distinct state dimension".into(),
                got: format!("{pos:?}"),
            });
        }
        Ok(Dynamics::SingleIntegrator { pos })
    }

    /// The unicycle reference point; `eps` finite and > 0, `x`, `y`, `theta` distinct.
    pub fn unicycle(eps: f64, x: usize, y: usize, theta: usize) -> Result<Self, InputError> {
        if !(eps.is_finite() && eps > 0.0) {
            return Err(InputError::Value {
                what: "Unicycle eps".into(),
                expected: "a finite distance > 0".into(),
                got: eps.to_string(),
            });
        }
        if x == y || x == theta || y == theta {
            return Err(InputError::Shape {
                what: "Unicycle dimensions".into(),
                expected: "distinct x, y, theta".into(),
                got: format!("x={x}, y={y}, theta={theta}"),
            });
        }
        Ok(Dynamics::Unicycle { eps, x, y, theta })
    }

    /// A double integrator: `pos` and `vel` non-empty, of equal length, all distinct.
    pub fn double_integrator(pos: Vec<usize>, vel: Vec<usize>) -> Result<Self, InputError> {
        if pos.is_empty() || pos.len() != vel.len() {
            return Err(InputError::Shape {
                what: "DoubleIntegrator pos, vel".into(),
                expected: "one velocity dimension per position dimension (at least one)".into(),
                got: format!("pos {pos:?}, vel {vel:?}"),
            });
        }
        distinct(
            "DoubleIntegrator pos + vel",
            &[pos.as_slice(), &vel].concat(),
        )?;
        Ok(Dynamics::DoubleIntegrator { pos, vel })
    }

    /// The acceleration-level unicycle; `x`, `y`, `theta`, `v` distinct.
    pub fn acceleration_unicycle(
        x: usize,
        y: usize,
        theta: usize,
        v: usize,
    ) -> Result<Self, InputError> {
        distinct("AccelerationUnicycle x, y, theta, v", &[x, y, theta, v])?;
        Ok(Dynamics::AccelerationUnicycle { x, y, theta, v })
    }

    /// The kinematic bicycle; wheelbase `l` finite and > 0, `x`, `y`, `theta`, `v` distinct.
    pub fn kinematic_bicycle(
        l: f64,
        x: usize,
        y: usize,
        theta: usize,
        v: usize,
    ) -> Result<Self, InputError> {
        if !(l.is_finite() && l > 0.0) {
            return Err(InputError::Value {
                what: "KinematicBicycle wheelbase".into(),
                expected: "a finite length > 0".into(),
                got: l.to_string(),
            });
        }
        distinct("KinematicBicycle x, y, theta, v", &[x, y, theta, v])?;
        Ok(Dynamics::KinematicBicycle { l, x, y, theta, v })
    }

    /// The thrust-and-turn body; `thrust` and `turn` finite and > 0, `drag` finite and
    /// >= 0, `dims = [x, y, theta, vx, vy]` distinct.
    pub fn thrust_turn(
        thrust: f64,
        turn: f64,
        drag: f64,
        dims: [usize; 5],
    ) -> Result<Self, InputError> {
        for (what, value, min_ok) in [
            ("thrust", thrust, false),
            ("turn", turn, false),
            ("drag", drag, true),
        ] {
            if !(value.is_finite() && (value > 0.0 || (min_ok && value == 0.0))) {
                return Err(InputError::Value {
                    what: format!("ThrustTurn {what}"),
                    expected: if min_ok {
                        "a finite number >= 0"
                    } else {
                        "a finite number > 0"
                    }
                    .into(),
                    got: value.to_string(),
                });
            }
        }
        distinct("ThrustTurn x, y, theta, vx, vy", &dims)?;
        let [x, y, theta, vx, vy] = dims;
        Ok(Dynamics::ThrustTurn {
            thrust,
            turn,
            drag,
            x,
            y,
            theta,
            vx,
            vy,
        })
    }

    /// The heading of an acceleration-level model whose turn input reaches the position only
    /// through the heading (the acceleration unicycle, the bicycle, ThrustTurn): the router's
    /// CLF adds a term that turns it towards where the CLF pushes (`shield/program.rs`).
    pub fn steered_heading(&self) -> Option<usize> {
        match *self {
            Dynamics::AccelerationUnicycle { theta, .. }
            | Dynamics::KinematicBicycle { theta, .. }
            | Dynamics::ThrustTurn { theta, .. } => Some(theta),
            Dynamics::SingleIntegrator { .. }
            | Dynamics::Unicycle { .. }
            | Dynamics::DoubleIntegrator { .. } => None,
        }
    }

    /// The speed's state index of a model that turns only while moving, the bicycle (its turn
    /// rate is `v tan delta / l`, nothing at rest). Guidance reads it to ask for the speed a
    /// turn needs where only a turn would bring the robot nearer (`crate::guidance`).
    pub fn turns_only_moving(&self) -> Option<usize> {
        match *self {
            Dynamics::KinematicBicycle { v, .. } => Some(v),
            _ => None,
        }
    }

    /// Whether the sample after next bends with the action: the next heading (or, for the
    /// bicycle, the turn the next speed allows) turns the step after it, so that a
    /// second-order sampled barrier row linearised at one action errs, to second order, at
    /// another (`shield/sampled.rs` linearises at the RL action for these models).
    pub fn bends_step(&self) -> bool {
        matches!(
            self,
            Dynamics::AccelerationUnicycle { .. } | Dynamics::KinematicBicycle { .. }
        )
    }

    /// The heading of a model that turns: the unicycle's (whose turn rate moves its reference
    /// point directly) and every [`Dynamics::steered_heading`]. Routing reads it to tell a turn
    /// into an obstacle the CBF blocks (`crate::guidance`), which it lets the CLF cancel.
    pub fn heading(&self) -> Option<usize> {
        match *self {
            Dynamics::Unicycle { theta, .. } => Some(theta),
            _ => self.steered_heading(),
        }
    }

    /// The number of inputs m.
    pub fn inputs(&self) -> usize {
        match self {
            Dynamics::SingleIntegrator { pos } | Dynamics::DoubleIntegrator { pos, .. } => {
                pos.len()
            }
            Dynamics::Unicycle { .. }
            | Dynamics::AccelerationUnicycle { .. }
            | Dynamics::KinematicBicycle { .. }
            | Dynamics::ThrustTurn { .. } => 2,
        }
    }

    /// The smallest state length the model can read.
    pub fn min_dim(&self) -> usize {
        let top = match self {
            Dynamics::SingleIntegrator { pos } => pos.iter().copied().max().unwrap_or(0),
            Dynamics::DoubleIntegrator { pos, vel } => {
                pos.iter().chain(vel).copied().max().unwrap_or(0)
            }
            Dynamics::Unicycle { x, y, theta, .. } => *x.max(y).max(theta),
            Dynamics::AccelerationUnicycle { x, y, theta, v }
            | Dynamics::KinematicBicycle { x, y, theta, v, .. } => *x.max(y).max(theta).max(v),
            Dynamics::ThrustTurn {
                x,
                y,
                theta,
                vx,
                vy,
                ..
            } => *x.max(y).max(theta).max(vx).max(vy),
        };
        top + 1
    }

    /// Whether an input can move state dimension `d` directly (row `d` of `g` may be
    /// non-zero). A barrier that reads no such dimension has relative degree 2 or more.
    pub fn actuates(&self, d: usize) -> bool {
        match self {
            Dynamics::SingleIntegrator { pos } => pos.contains(&d),
            Dynamics::DoubleIntegrator { vel, .. } => vel.contains(&d),
            Dynamics::Unicycle { x, y, theta, .. } => d == *x || d == *y || d == *theta,
            Dynamics::AccelerationUnicycle { theta, v, .. }
            | Dynamics::KinematicBicycle { theta, v, .. } => d == *theta || d == *v,
            Dynamics::ThrustTurn { theta, vx, vy, .. } => d == *theta || d == *vx || d == *vy,
        }
    }

    /// Whether an input moves state dimension `d` through one integration (the dimension has
    /// relative degree 2: `d` is a position of an acceleration-level model).
    pub fn actuates_twice_removed(&self, d: usize) -> bool {
        match self {
            Dynamics::SingleIntegrator { .. } | Dynamics::Unicycle { .. } => false,
            Dynamics::DoubleIntegrator { pos, .. } => pos.contains(&d),
            Dynamics::AccelerationUnicycle { x, y, .. }
            | Dynamics::KinematicBicycle { x, y, .. }
            | Dynamics::ThrustTurn { x, y, .. } => d == *x || d == *y,
        }
    }

    /// `out = J_f(s) u`, the Jacobian of the drift `f` times `u` (lengths n).
    pub fn jacobian_f_times(&self, s: &[f64], u: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        match self {
            Dynamics::SingleIntegrator { .. } | Dynamics::Unicycle { .. } => {}
            Dynamics::DoubleIntegrator { pos, vel } => {
                for (&p, &w) in pos.iter().zip(vel) {
                    out[p] = u[w];
                }
            }
            // The bicycle's drift is the acceleration unicycle's: steering enters through g.
            Dynamics::AccelerationUnicycle { x, y, theta, v }
            | Dynamics::KinematicBicycle { x, y, theta, v, .. } => {
                let (sin, cos) = s[*theta].sin_cos();
                out[*x] = -s[*v] * sin * u[*theta] + cos * u[*v];
                out[*y] = s[*v] * cos * u[*theta] + sin * u[*v];
            }
            Dynamics::ThrustTurn {
                drag, x, y, vx, vy, ..
            } => {
                out[*x] = u[*vx];
                out[*y] = u[*vy];
                out[*vx] = -drag * u[*vx];
                out[*vy] = -drag * u[*vy];
            }
        }
    }

    /// `out = J_f(s)^T w` (lengths n).
    pub fn jacobian_f_transpose_times(&self, s: &[f64], w: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        match self {
            Dynamics::SingleIntegrator { .. } | Dynamics::Unicycle { .. } => {}
            Dynamics::DoubleIntegrator { pos, vel } => {
                for (&p, &q) in pos.iter().zip(vel) {
                    out[q] = w[p];
                }
            }
            Dynamics::AccelerationUnicycle { x, y, theta, v }
            | Dynamics::KinematicBicycle { x, y, theta, v, .. } => {
                let (sin, cos) = s[*theta].sin_cos();
                out[*theta] = s[*v] * (-sin * w[*x] + cos * w[*y]);
                out[*v] = cos * w[*x] + sin * w[*y];
            }
            Dynamics::ThrustTurn {
                drag, x, y, vx, vy, ..
            } => {
                out[*vx] = w[*x] - drag * w[*vx];
                out[*vy] = w[*y] - drag * w[*vy];
            }
        }
    }

    /// `out_i = sum_{k,j} u_k v_j dg_kj/ds_i` (u length n, v length m, out length n): how
    /// `u' g(s) v` moves with the state, which the state gradient of a shielded action needs.
    /// Zero for the models whose `g` is constant.
    pub fn input_jacobian_contract(&self, s: &[f64], u: &[f64], v: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        match self {
            Dynamics::SingleIntegrator { .. }
            | Dynamics::DoubleIntegrator { .. }
            | Dynamics::AccelerationUnicycle { .. } => {}
            Dynamics::Unicycle { eps, x, y, theta } => {
                let (sin, cos) = s[*theta].sin_cos();
                out[*theta] = u[*x] * (-sin * v[0] - eps * cos * v[1])
                    + u[*y] * (cos * v[0] - eps * sin * v[1]);
            }
            Dynamics::KinematicBicycle {
                l, theta, v: speed, ..
            } => {
                out[*speed] = u[*theta] * v[1] / l;
            }
            Dynamics::ThrustTurn {
                thrust,
                theta,
                vx,
                vy,
                ..
            } => {
                let (sin, cos) = s[*theta].sin_cos();
                out[*theta] = thrust * v[0] * (-sin * u[*vx] + cos * u[*vy]);
            }
        }
    }

    /// Checks a state for this model: at least [`Dynamics::min_dim`] values, all finite.
    pub fn check_state(&self, s: &[f64]) -> Result<(), InputError> {
        if s.len() < self.min_dim() {
            return Err(InputError::Shape {
                what: "s".into(),
                expected: format!("at least {} values for this model", self.min_dim()),
                got: s.len().to_string(),
            });
        }
        check_finite("s", s, s.len())
    }

    /// [`Dynamics::euler_step`] after checking `s`, `a` (m finite values) and `dt` (finite,
    /// > 0); returns the next state.
    pub fn checked_euler_step(
        &self,
        s: &[f64],
        a: &[f64],
        dt: f64,
    ) -> Result<Vec<f64>, InputError> {
        self.check_state(s)?;
        check_step_input(a, self.inputs(), dt)?;
        let mut out = vec![0.0; s.len()];
        self.euler_step(s, a, dt, &mut out);
        Ok(out)
    }

    /// Writes `ds/dt = f(s) + g(s) a` into `out` (length n) without building `f` and `g`;
    /// equal to them by construction and by test. `a` has length m.
    pub fn derivative(&self, s: &[f64], a: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        match self {
            Dynamics::SingleIntegrator { pos } => {
                for (&p, &ai) in pos.iter().zip(a) {
                    out[p] = ai;
                }
            }
            Dynamics::Unicycle { eps, x, y, theta } => {
                let (sin, cos) = s[*theta].sin_cos();
                out[*x] = cos * a[0] - eps * sin * a[1];
                out[*y] = sin * a[0] + eps * cos * a[1];
                out[*theta] = a[1];
            }
            Dynamics::DoubleIntegrator { pos, vel } => {
                for ((&p, &v), &ai) in pos.iter().zip(vel).zip(a) {
                    out[p] = s[v];
                    out[v] = ai;
                }
            }
            Dynamics::AccelerationUnicycle { x, y, theta, v } => {
                let (sin, cos) = s[*theta].sin_cos();
                out[*x] = s[*v] * cos;
                out[*y] = s[*v] * sin;
                out[*theta] = a[1];
                out[*v] = a[0];
            }
            Dynamics::KinematicBicycle { l, x, y, theta, v } => {
                let (sin, cos) = s[*theta].sin_cos();
                out[*x] = s[*v] * cos;
                out[*y] = s[*v] * sin;
                out[*theta] = s[*v] * a[1] / l;
                out[*v] = a[0];
            }
            Dynamics::ThrustTurn {
                thrust,
                turn,
                drag,
                x,
                y,
                theta,
                vx,
                vy,
            } => {
                let (sin, cos) = s[*theta].sin_cos();
                out[*x] = s[*vx];
                out[*y] = s[*vy];
                out[*theta] = turn * a[1];
                out[*vx] = thrust * a[0] * cos - drag * s[*vx];
                out[*vy] = thrust * a[0] * sin - drag * s[*vy];
            }
        }
    }

    /// One explicit Euler step `out = s + dt (f(s) + g(s) a)`: the plant that environments
    /// built on this model integrate, so the plant and the shield's model are one code.
    pub fn euler_step(&self, s: &[f64], a: &[f64], dt: f64, out: &mut [f64]) {
        self.derivative(s, a, out);
        for (o, &si) in out.iter_mut().zip(s) {
            *o = si + dt * *o;
        }
    }

    /// Writes `f(s)` (length n) and `g(s)` (n x m, row-major) for state `s`.
    pub fn eval(&self, s: &[f64], f: &mut [f64], g: &mut [f64]) {
        f.fill(0.0);
        g.fill(0.0);
        let m = self.inputs();
        match self {
            Dynamics::SingleIntegrator { pos } => {
                for (i, &p) in pos.iter().enumerate() {
                    g[p * m + i] = 1.0;
                }
            }
            Dynamics::Unicycle { eps, x, y, theta } => {
                let (sin, cos) = s[*theta].sin_cos();
                g[x * m] = cos;
                g[x * m + 1] = -eps * sin;
                g[y * m] = sin;
                g[y * m + 1] = eps * cos;
                g[theta * m + 1] = 1.0;
            }
            Dynamics::DoubleIntegrator { pos, vel } => {
                for (i, (&p, &v)) in pos.iter().zip(vel).enumerate() {
                    f[p] = s[v];
                    g[v * m + i] = 1.0;
                }
            }
            Dynamics::AccelerationUnicycle { x, y, theta, v } => {
                let (sin, cos) = s[*theta].sin_cos();
                f[*x] = s[*v] * cos;
                f[*y] = s[*v] * sin;
                g[v * m] = 1.0;
                g[theta * m + 1] = 1.0;
            }
            Dynamics::KinematicBicycle { l, x, y, theta, v } => {
                let (sin, cos) = s[*theta].sin_cos();
                f[*x] = s[*v] * cos;
                f[*y] = s[*v] * sin;
                g[v * m] = 1.0;
                g[theta * m + 1] = s[*v] / l;
            }
            Dynamics::ThrustTurn {
                thrust,
                turn,
                drag,
                x,
                y,
                theta,
                vx,
                vy,
            } => {
                let (sin, cos) = s[*theta].sin_cos();
                f[*x] = s[*vx];
                f[*y] = s[*vy];
                f[*vx] = -drag * s[*vx];
                f[*vy] = -drag * s[*vy];
                g[vx * m] = thrust * cos;
                g[vy * m] = thrust * sin;
                g[theta * m + 1] = *turn;
            }
        }
    }
}

/// The model as its Python constructor writes it, e.g. `DoubleIntegrator(pos=[0, 1], vel=[2, 3])`.
impl std::fmt::Display for Dynamics {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Dynamics::SingleIntegrator { pos } => write!(f, "SingleIntegrator(pos={pos:?})"),
            Dynamics::Unicycle { eps, x, y, theta } => {
                write!(f, "Unicycle(eps={eps}, x={x}, y={y}, theta={theta})")
            }
            Dynamics::DoubleIntegrator { pos, vel } => {
                write!(f, "DoubleIntegrator(pos={pos:?}, vel={vel:?})")
            }
            Dynamics::AccelerationUnicycle { x, y, theta, v } => {
                write!(
                    f,
                    "AccelerationUnicycle(x={x}, y={y}, theta={theta}, v={v})"
                )
            }
            Dynamics::KinematicBicycle { l, x, y, theta, v } => {
                write!(
                    f,
                    "KinematicBicycle(wheelbase={l}, x={x}, y={y}, theta={theta}, v={v})"
                )
            }
            Dynamics::ThrustTurn {
                thrust,
                turn,
                drag,
                x,
                y,
                theta,
                vx,
                vy,
            } => write!(
                f,
                "ThrustTurn(thrust={thrust}, turn={turn}, drag={drag}, x={x}, y={y}, \
                 theta={theta}, vx={vx}, vy={vy})"
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unicycle_reference_point_matches_eq_6a2() {
        let d = Dynamics::unicycle(0.1, 0, 1, 2).unwrap();
        let s = [0.0, 0.0, std::f64::consts::FRAC_PI_2];
        let (mut f, mut g) = ([9.0; 3], [9.0; 6]);
        d.eval(&s, &mut f, &mut g);
        assert_eq!(f, [0.0; 3]);
        // theta = 90 degrees: a_v moves +y, a_theta moves the reference point -x by eps.
        let expect = [0.0, -0.1, 1.0, 0.0, 0.0, 1.0];
        for (a, b) in g.iter().zip(expect) {
            assert!((a - b).abs() < 1e-15);
        }
    }

    #[test]
    fn bad_models() {
        crate::tests_support::assert_error(
            Dynamics::unicycle(0.0, 0, 1, 2),
            "Value",
            "Unicycle eps",
        );
        crate::tests_support::assert_error(
            Dynamics::unicycle(0.1, 0, 0, 2),
            "Shape",
            "Unicycle dimensions",
        );
        crate::tests_support::assert_error(
            Dynamics::single_integrator(vec![]),
            "Value",
            "SingleIntegrator pos",
        );
        crate::tests_support::assert_error(
            Dynamics::single_integrator(vec![1, 1]),
            "Value",
            "SingleIntegrator pos",
        );
        crate::tests_support::assert_error(
            Dynamics::double_integrator(vec![0, 1], vec![2]),
            "Shape",
            "DoubleIntegrator pos, vel",
        );
        crate::tests_support::assert_error(
            Dynamics::double_integrator(vec![0, 1], vec![1, 2]),
            "Shape",
            "DoubleIntegrator pos + vel",
        );
        crate::tests_support::assert_error(
            Dynamics::acceleration_unicycle(0, 1, 2, 2),
            "Shape",
            "AccelerationUnicycle x, y, theta, v",
        );
        crate::tests_support::assert_error(
            Dynamics::kinematic_bicycle(0.0, 0, 1, 2, 3),
            "Value",
            "KinematicBicycle wheelbase",
        );
        crate::tests_support::assert_error(
            Dynamics::kinematic_bicycle(f64::NAN, 0, 1, 2, 3),
            "Value",
            "KinematicBicycle wheelbase",
        );
        crate::tests_support::assert_error(
            Dynamics::kinematic_bicycle(0.5, 0, 1, 1, 3),
            "Shape",
            "KinematicBicycle x, y, theta, v",
        );
        crate::tests_support::assert_error(
            Dynamics::thrust_turn(0.0, 1.0, 1.0, [0, 1, 2, 3, 4]),
            "Value",
            "ThrustTurn thrust",
        );
        crate::tests_support::assert_error(
            Dynamics::thrust_turn(1.0, f64::INFINITY, 1.0, [0, 1, 2, 3, 4]),
            "Value",
            "ThrustTurn turn",
        );
        crate::tests_support::assert_error(
            Dynamics::thrust_turn(1.0, 1.0, -0.1, [0, 1, 2, 3, 4]),
            "Value",
            "ThrustTurn drag",
        );
        crate::tests_support::assert_error(
            Dynamics::thrust_turn(1.0, 1.0, 0.0, [0, 1, 2, 3, 3]),
            "Shape",
            "ThrustTurn x, y, theta, vx, vy",
        );
        assert!(Dynamics::thrust_turn(1.0, 1.0, 0.0, [0, 1, 2, 3, 4]).is_ok());
    }

    /// Every built-in model over a five-value state, with dimensions permuted.
    fn models_over_five() -> [Dynamics; 6] {
        [
            Dynamics::single_integrator(vec![1, 4]).unwrap(),
            Dynamics::double_integrator(vec![0, 1], vec![3, 2]).unwrap(),
            Dynamics::acceleration_unicycle(4, 1, 2, 0).unwrap(),
            Dynamics::unicycle(0.1, 0, 1, 2).unwrap(),
            Dynamics::kinematic_bicycle(0.5, 3, 1, 4, 0).unwrap(),
            Dynamics::thrust_turn(2.8, 3.2, 1.9, [3, 1, 4, 0, 2]).unwrap(),
        ]
    }

    proptest::proptest! {
        #![proptest_config(crate::tests_support::seeded(300))]

        /// The Jacobian products equal central finite differences of `f`, and the two are
        /// transposes of each other: `w . (J u) == (J^T w) . u`.
        #[test]
        fn jacobian_products_match_finite_differences(
            s in proptest::collection::vec(-3.0..3.0f64, 5),
            u in proptest::collection::vec(-2.0..2.0f64, 5),
            w in proptest::collection::vec(-2.0..2.0f64, 5),
        ) {
            for model in models_over_five() {
                let m = model.inputs();
                let f_at = |x: &[f64]| {
                    let (mut f, mut g) = (vec![0.0; 5], vec![0.0; 5 * m]);
                    model.eval(x, &mut f, &mut g);
                    f
                };
                let h = 1e-6;
                let plus: Vec<f64> = s.iter().zip(&u).map(|(a, b)| a + h * b).collect();
                let minus: Vec<f64> = s.iter().zip(&u).map(|(a, b)| a - h * b).collect();
                let (fp, fm) = (f_at(&plus), f_at(&minus));
                let mut ju = vec![0.0; 5];
                model.jacobian_f_times(&s, &u, &mut ju);
                for i in 0..5 {
                    let fd = (fp[i] - fm[i]) / (2.0 * h);
                    proptest::prop_assert!((ju[i] - fd).abs() < 1e-6, "{model:?} row {i}");
                }
                let mut jtw = vec![0.0; 5];
                model.jacobian_f_transpose_times(&s, &w, &mut jtw);
                let lhs: f64 = w.iter().zip(&ju).map(|(a, b)| a * b).sum();
                let rhs: f64 = jtw.iter().zip(&u).map(|(a, b)| a * b).sum();
                proptest::prop_assert!((lhs - rhs).abs() < 1e-12);
                // Structure: g's non-zero rows are exactly the actuated dimensions.
                let (mut f, mut g) = (vec![0.0; 5], vec![0.0; 5 * m]);
                model.eval(&s, &mut f, &mut g);
                for d in 0..5 {
                    if !model.actuates(d) {
                        proptest::prop_assert!(g[d * m..(d + 1) * m].iter().all(|&x| x == 0.0));
                    }
                }
            }
        }
    }

    proptest::proptest! {
        #![proptest_config(crate::tests_support::seeded(300))]

        /// `input_jacobian_contract` is the gradient of `u' g(s) v`, by central differences.
        #[test]
        fn input_jacobian_contract_matches_finite_differences(
            s in proptest::collection::vec(-3.0..3.0f64, 5),
            u in proptest::collection::vec(-2.0..2.0f64, 5),
            v in proptest::collection::vec(-2.0..2.0f64, 2),
        ) {
            for model in models_over_five() {
                let m = model.inputs();
                let ugv = |x: &[f64]| {
                    let (mut f, mut g) = (vec![0.0; 5], vec![0.0; 5 * m]);
                    model.eval(x, &mut f, &mut g);
                    (0..5).map(|k| (0..m).map(|j| u[k] * g[k * m + j] * v[j]).sum::<f64>()).sum::<f64>()
                };
                let mut out = vec![0.0; 5];
                model.input_jacobian_contract(&s, &u, &v[..m], &mut out);
                for i in 0..5 {
                    let (mut p, mut q) = (s.clone(), s.clone());
                    p[i] += 1e-6;
                    q[i] -= 1e-6;
                    let fd = (ugv(&p) - ugv(&q)) / 2e-6;
                    proptest::prop_assert!((out[i] - fd).abs() < 1e-6, "{model:?} dim {i}");
                }
            }
        }
    }

    proptest::proptest! {
        #![proptest_config(crate::tests_support::seeded(500))]

        #[test]
        fn euler_step_is_s_plus_dt_f_plus_g_a(
            s in proptest::collection::vec(-4.0..4.0f64, 5),
            a in proptest::collection::vec(-3.0..3.0f64, 2),
            dt in 0.001..0.5f64,
        ) {
            for model in [
                Dynamics::unicycle(0.1, 0, 1, 2).unwrap(),
                Dynamics::unicycle(0.3, 3, 4, 0).unwrap(),
                Dynamics::single_integrator(vec![1, 4]).unwrap(),
                Dynamics::double_integrator(vec![0, 1], vec![3, 2]).unwrap(),
                Dynamics::acceleration_unicycle(0, 1, 2, 3).unwrap(),
                Dynamics::kinematic_bicycle(0.5, 0, 1, 2, 3).unwrap(),
                Dynamics::thrust_turn(2.8, 3.2, 1.9, [0, 1, 2, 3, 4]).unwrap(),
            ] {
                let m = model.inputs();
                let (mut f, mut g, mut out) = (vec![0.0; 5], vec![0.0; 5 * m], vec![0.0; 5]);
                model.eval(&s, &mut f, &mut g);
                model.euler_step(&s, &a[..m], dt, &mut out);
                for i in 0..5 {
                    let gi: f64 = (0..m).map(|j| g[i * m + j] * a[j]).sum();
                    let want = s[i] + dt * (f[i] + gi);
                    proptest::prop_assert!((out[i] - want).abs() <= 1e-12 * (1.0 + want.abs()));
                }
            }
        }
    }
}

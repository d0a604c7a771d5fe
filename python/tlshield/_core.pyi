"""Type stubs for the compiled module ``tlshield._core`` (hand-written; keep in sync)."""

from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar, Literal, TypeAlias, final

import numpy as np
from numpy.typing import ArrayLike, NDArray
from typing_extensions import Self

from tlshield.codes import Solver, Status
from tlshield.envs.channel_task import ChannelParams

__version__: str

def formula_atoms(formula: str) -> list[str]:
    """Parses an scTLTL formula and returns its atoms in order of first appearance."""

def _restore(
    version: object,
    make: Callable[..., Any],
    args: tuple[Any, ...],
    kwargs: dict[str, Any] | None = None,
) -> Any:
    """Rebuilds a pickled tlshield object (refuses a pickle of another version)."""

DEFAULT_C_R: float
DEFAULT_TRAP_PENALTY: float
DEFAULT_GAMMA: float
DEFAULT_HORIZON: int
DEFAULT_PROGRESS_SCALE: float
GRAD_RELAXED: int
GRAD_FAILED: int
GRAD_DEGENERATE: int
GRAD_SINGULAR: int
GRAD_ROUTED: int
STATUS_CODES: dict[str, int]
SOLVER_CODES: dict[str, int]

class SpecError(ValueError):
    """A formula that does not parse or is not scTLTL, or predicates that do not fit it."""

class AutomatonError(ValueError):
    """A problem building or using an automaton (too many atoms, an unknown state, a reward
    asked of the trap)."""

class ShieldError(ValueError):
    """A problem configuring or calling a shield (a bad parameter, a state or action that does
    not fit it)."""

@final
class Halfspace:
    """Half-space predicate ``rho(s) = w . s + b`` (holds iff > 0)."""

    def __new__(cls, w: ArrayLike, b: float) -> Self: ...
    def robustness(self, s: ArrayLike) -> float: ...
    def gradient(self, s: ArrayLike) -> NDArray[np.float64]: ...
    @property
    def w(self) -> NDArray[np.float64]: ...
    @property
    def b(self) -> float: ...

@final
class Ball:
    """Ball predicate ``rho(s) = radius - |p(s) - c|``; centre fixed or read from the state.

    ``p(s)`` is ``s[pos]``, or with ``heading`` and ``offset = (along, across)`` the point of the
    body ``s[pos] + R(s[heading]) offset`` (metres ahead of and left of ``s[pos]``)."""

    def __new__(
        cls,
        pos: Sequence[int],
        radius: float,
        center: ArrayLike | None = None,
        center_dims: Sequence[int] | None = None,
        heading: int | None = None,
        offset: ArrayLike | None = None,
    ) -> Self: ...
    def robustness(self, s: ArrayLike) -> float: ...
    def gradient(self, s: ArrayLike) -> NDArray[np.float64]: ...
    @property
    def pos(self) -> list[int]: ...
    @property
    def radius(self) -> float: ...
    @property
    def center(self) -> list[float] | None: ...
    @property
    def center_dims(self) -> list[int] | None: ...
    @property
    def heading(self) -> int | None: ...
    @property
    def offset(self) -> tuple[float, float] | None: ...

@final
class Union:
    """A union of regions: holds where any part holds (robustness: the largest part's)."""

    def __new__(cls, parts: Sequence[PredicateLike]) -> Self: ...
    def robustness(self, s: ArrayLike) -> float: ...
    def gradient(self, s: ArrayLike) -> NDArray[np.float64]: ...
    @property
    def parts(self) -> list[Predicate]: ...

@final
class Intersection:
    """An intersection of regions: holds where every part holds (robustness: the smallest)."""

    def __new__(cls, parts: Sequence[PredicateLike]) -> Self: ...
    def robustness(self, s: ArrayLike) -> float: ...
    def gradient(self, s: ArrayLike) -> NDArray[np.float64]: ...
    @property
    def parts(self) -> list[Predicate]: ...

Predicate: TypeAlias = Halfspace | Ball | Union | Intersection
#: A predicate, or a list or tuple of them (their union).
PredicateLike: TypeAlias = Predicate | Sequence[Predicate]

@final
class Avoid:
    """A barrier that keeps the state out of the predicate's region: ``h = -rho(predicate)``
    (``Shield(barriers={"shelf": Avoid(ball)})``)."""

    def __new__(cls, predicate: PredicateLike) -> Self: ...
    @property
    def predicate(self) -> Predicate: ...

@final
class Inside:
    """A barrier that keeps the state in the predicate's region: ``h = rho(predicate)``
    (``Shield(barriers={"arena": Inside(halfspace)})``)."""

    def __new__(cls, predicate: PredicateLike) -> Self: ...
    @property
    def predicate(self) -> Predicate: ...

#: A user barrier: its side stated by its type, optionally with a slack weight.
BarrierLike: TypeAlias = Avoid | Inside | tuple[Avoid | Inside, float]

@final
class Spec:
    """An scTLTL formula over named state predicates."""

    def __new__(
        cls,
        formula: str,
        predicates: Mapping[str, PredicateLike],
        exclusive: Sequence[Sequence[str]] | None = None,
    ) -> Self: ...
    @property
    def atoms(self) -> list[str]: ...
    @property
    def exclusive(self) -> list[list[str]]: ...
    @property
    def predicates(self) -> dict[str, Predicate]: ...
    def atom_robustness(self, s: ArrayLike) -> NDArray[np.float64]: ...
    def robustness(self, traj: ArrayLike) -> float: ...
    def satisfied(self, traj: ArrayLike) -> bool: ...
    def robustness_batch(self, trajs: ArrayLike) -> NDArray[np.float64]: ...
    def automaton(self) -> Automaton: ...

@final
class Automaton:
    """The finite state automaton of an scTLTL spec (see ``Spec.automaton()``)."""

    @property
    def num_states(self) -> int: ...
    @property
    def diagram_nodes(self) -> int: ...
    @property
    def initial(self) -> int: ...
    @property
    def accepting(self) -> list[int]: ...
    @property
    def trap(self) -> int | None: ...
    @property
    def atoms(self) -> list[str]: ...
    @property
    def spec(self) -> Spec: ...
    @staticmethod
    def from_formula(formula: str) -> Automaton:
        """The automaton of a formula alone (no predicates): structure only, no state queries."""
    def edges(self) -> list[tuple[int, int, str]]: ...
    def to_dot(self) -> str: ...
    def step(self, s: ArrayLike, q: int) -> int: ...
    def step_batch(self, states: ArrayLike, qs: ArrayLike) -> NDArray[np.int64]: ...
    def run(self, traj: ArrayLike) -> int: ...
    def accepts(self, traj: ArrayLike) -> bool: ...
    def reward(
        self, s_next: ArrayLike, q: int, c_r: float, trap_penalty: float | None = None
    ) -> float: ...
    def trap_cnf(self, q: int) -> list[list[str]]: ...
    @property
    def recovery_cnf(self) -> list[list[str]]:
        """The trap's recovery safe set (what every way into the trap kept)."""
    def avoid_cnf(self, q: int) -> list[list[str]]: ...
    @property
    def ranks(self) -> list[int | None]: ...
    def safe_set(
        self, s: ArrayLike, q: int, preserve_progress: bool = False
    ) -> list[tuple[str, float]]: ...
    def goal(self, s: ArrayLike, q: int) -> NDArray[np.float64] | None: ...
    def progress_reward(
        self,
        *,
        gamma: float = ...,
        horizon: int = ...,
        scale: float = ...,
        step_cost: float | None = None,
        bonus: float | None = None,
        c_r: float = ...,
        exclusive: Sequence[Sequence[str]] | None = None,
        goal_weight: float = 0.0,
        goal_span: float = ...,
    ) -> ProgressReward: ...

@final
class ProgressReward:
    """The progress-aware task reward of an automaton (see ``Automaton.progress_reward``)."""

    @property
    def ranks(self) -> list[int | None]: ...
    @property
    def step_cost(self) -> float: ...
    @property
    def bonus(self) -> float: ...
    @property
    def trap_penalty(self) -> float: ...
    @property
    def gamma(self) -> float: ...
    @property
    def horizon(self) -> int: ...
    @property
    def goal_weight(self) -> float: ...
    @property
    def goal_span(self) -> float: ...
    def potential(self, s: ArrayLike, q: int) -> float: ...

@final
class TaskStep:
    """What one step of the task gives (``Monitor.reset`` and ``Monitor.advance``)."""

    @property
    def q(self) -> int: ...
    @property
    def reward(self) -> float: ...
    @property
    def accepted(self) -> bool: ...
    @property
    def trapped(self) -> bool: ...
    @property
    def goal(self) -> NDArray[np.float64] | None: ...
    @property
    def atom_robustness(self) -> NDArray[np.float64]: ...

@final
class Monitor:
    """The task automaton along one episode: ``q``, the last reading of the atoms and the task
    reward's state; ``reset(s0)`` and ``advance(s_next)`` give a ``TaskStep`` in one call, and
    ``Shield.filter_monitor(monitor, a_rl)`` reuses the reading."""

    def __new__(
        cls,
        automaton: Automaton,
        progress: ProgressReward | None = None,
        *,
        c_r: float = 1.0,
        trap_penalty: float = -100.0,
        routed_by: Shield | None = None,
    ) -> Self: ...
    @property
    def routed_by(self) -> Shield | None: ...
    @routed_by.setter
    def routed_by(self, shield: Shield | None) -> None: ...
    @property
    def goal_distance(self) -> float | None: ...
    def reset(self, s0: ArrayLike) -> TaskStep: ...
    def advance(self, s_next: ArrayLike) -> TaskStep: ...
    @property
    def q(self) -> int: ...
    @property
    def phi(self) -> float: ...
    @property
    def started(self) -> bool: ...
    @property
    def automaton(self) -> Automaton: ...
    @property
    def state(self) -> NDArray[np.float64]: ...
    @property
    def goal(self) -> NDArray[np.float64] | None: ...

@final
class TaskBatch:
    """What one batch step of the task gives, one row per monitor."""

    @property
    def q(self) -> NDArray[np.int64]: ...
    @property
    def reward(self) -> NDArray[np.float64]: ...
    @property
    def accepted(self) -> NDArray[np.bool_]: ...
    @property
    def trapped(self) -> NDArray[np.bool_]: ...
    def __len__(self) -> int: ...

@final
class MonitorBatch:
    """``num`` task monitors of one automaton, stepped together (the batch twin of
    ``Monitor``); ``Shield.filter_monitors(monitors, a_rl)`` reuses the rows' readings."""

    def __new__(
        cls,
        automaton: Automaton,
        num: int,
        progress: ProgressReward | None = None,
        *,
        c_r: float = 1.0,
        trap_penalty: float = -100.0,
        routed_by: Shield | None = None,
    ) -> Self: ...
    @property
    def routed_by(self) -> Shield | None: ...
    @routed_by.setter
    def routed_by(self, shield: Shield | None) -> None: ...
    def reset(self, states: ArrayLike, rows: ArrayLike | None = None) -> TaskBatch: ...
    def advance(self, states: ArrayLike) -> TaskBatch: ...
    @property
    def q(self) -> NDArray[np.int64]: ...
    @property
    def states(self) -> NDArray[np.float64]: ...
    @property
    def automaton(self) -> Automaton: ...
    def __len__(self) -> int: ...

@final
class WorldStep:
    """What one step of a bundled world gives (``ChannelWorld.step``, ``PointMassWorld.step``)."""

    @property
    def observation(self) -> NDArray[np.float64]: ...
    @property
    def a_rl(self) -> NDArray[np.float64]: ...
    @property
    def action(self) -> NDArray[np.float64]: ...
    @property
    def shield(self) -> FilterResult | None: ...
    @property
    def q(self) -> int: ...
    @property
    def tl_reward(self) -> float: ...
    @property
    def accepted(self) -> bool: ...
    @property
    def trapped(self) -> bool: ...
    @property
    def reward(self) -> float: ...
    @property
    def terminated(self) -> bool: ...
    @property
    def truncated(self) -> bool: ...
    @property
    def constraints(self) -> tuple[float, float]: ...
    @property
    def min_obstacle_distance(self) -> float: ...
    @property
    def collision(self) -> bool: ...
    @property
    def violation(self) -> bool: ...

@final
class ChannelWorld:
    """The paper's case study (Sec. VI) stepped in the core: plant, obstacles, shield call,
    task monitor, reward terms and observation in one call (``tlshield/Channel-v0`` is a
    Gymnasium shell around it)."""

    STATE_DIM: ClassVar[int]
    RELATIVE_DIM: ClassVar[int]
    X: ClassVar[int]
    Y: ClassVar[int]
    THETA: ClassVar[int]
    GOAL_DIMS: ClassVar[list[tuple[int, int]]]
    OBSTACLE_DIMS: ClassVar[list[tuple[int, int]]]
    @staticmethod
    def xy(u: float, v: float) -> tuple[float, float]: ...
    def rl_action(self, action: ArrayLike) -> NDArray[np.float64]:
        """Policy actions ``(N, 2)`` in ``[-1, 1]`` scaled to the RL box."""
    def __new__(
        cls,
        model: Unicycle,
        params: ChannelParams,
        *,
        evaluation: bool,
        channel_atoms: tuple[int, int],
    ) -> Self: ...
    def reset(self, s0: ArrayLike, obstacles: ArrayLike) -> None: ...
    def step(
        self,
        action: ArrayLike,
        monitor: Monitor,
        shield: Shield | None = None,
        scale: bool = True,
    ) -> WorldStep: ...
    def observe(self, monitor: Monitor) -> NDArray[np.float64]: ...
    def measure(self, monitor: Monitor) -> tuple[float, float, float, bool, bool]: ...
    @property
    def state(self) -> NDArray[np.float64]: ...
    @property
    def drift(self) -> NDArray[np.float64]: ...
    @property
    def steps(self) -> int: ...

@final
class WorldsStep:
    """What one ``step_worlds`` call gives, one row per world."""

    @property
    def observation(self) -> NDArray[np.float64]: ...
    @property
    def reward(self) -> NDArray[np.float64]: ...
    @property
    def terminated(self) -> NDArray[np.bool_]: ...
    @property
    def truncated(self) -> NDArray[np.bool_]: ...
    @property
    def q(self) -> NDArray[np.int64]: ...
    @property
    def tl_reward(self) -> NDArray[np.float64]: ...
    @property
    def accepted(self) -> NDArray[np.bool_]: ...
    @property
    def trapped(self) -> NDArray[np.bool_]: ...
    @property
    def constraints(self) -> NDArray[np.float64]: ...
    @property
    def min_obstacle_distance(self) -> NDArray[np.float64]: ...
    @property
    def collision(self) -> NDArray[np.bool_]: ...
    @property
    def violation(self) -> NDArray[np.bool_]: ...
    @property
    def a_rl(self) -> NDArray[np.float64]: ...
    @property
    def action(self) -> NDArray[np.float64]: ...
    @property
    def a_cbf(self) -> NDArray[np.float64]: ...
    @property
    def a_clf(self) -> NDArray[np.float64]: ...
    @property
    def delta(self) -> NDArray[np.float64]: ...
    @property
    def slack(self) -> NDArray[np.float64]: ...
    @property
    def status(self) -> NDArray[np.uint8]: ...
    @property
    def solver(self) -> NDArray[np.uint8]: ...
    @property
    def gave_way(self) -> list[tuple[str, float] | None]: ...
    @property
    def active(self) -> NDArray[np.bool_]: ...
    def infos(
        self,
        constraints: tuple[str, str],
        shield: bool,
        status_of: dict[int, Any],
        solver_of: dict[int, Any],
    ) -> list[dict[str, Any]]:
        """Each row's ``info`` as the single env's ``step`` gives it, but the CLF goal and the
        barrier list (None and empty): ``constraints`` names the two constraints, ``shield``
        says whether rows carry ``info["shield"]``, and ``status_of`` / ``solver_of`` map the
        status and solver codes to their enum members (a code they lack gives None)."""

def step_worlds(
    worlds: Sequence[ChannelWorld] | Sequence[PointMassWorld],
    monitors: Sequence[Monitor],
    actions: ArrayLike,
    obs: ArrayLike,
    active: Sequence[bool] | None = None,
    shield: Shield | None = None,
    scale: bool = True,
) -> WorldsStep:
    """Steps the worlds in one call (parallel past 32 rows, GIL released)."""

@final
class PointMassWorld:
    """``tlshield/PointMass-v0`` stepped in the core: shield call, acceleration box, double
    integrator, walls, task monitor, reward and observation in one call."""

    STATE_DIM: ClassVar[int]
    POS: ClassVar[tuple[int, int]]
    VEL: ClassVar[tuple[int, int]]

    def __new__(
        cls,
        *,
        dt: float,
        horizon: int,
        room: tuple[float, float],
        max_accel: float,
        obstacles: tuple[tuple[float, float], tuple[float, float]],
        obstacle_radius: float,
        collision_penalty: float,
    ) -> Self: ...
    def reset(self, s0: ArrayLike) -> None: ...
    def step(
        self, a_rl: ArrayLike, monitor: Monitor, shield: Shield | None = None
    ) -> WorldStep: ...
    def measure(self) -> tuple[float, float, float, bool]: ...
    @property
    def state(self) -> NDArray[np.float64]: ...
    @property
    def steps(self) -> int: ...

@final
class Unicycle:
    """The unicycle's reference point ``eps`` ahead of its centre (paper Eq. 6A2)."""

    def __new__(cls, eps: float, x: int = 0, y: int = 1, theta: int = 2) -> Self: ...
    def eval(self, s: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...
    def step(self, s: ArrayLike, a: ArrayLike, dt: float) -> NDArray[np.float64]:
        """One Euler step ``s + dt (f(s) + g(s) a)``."""

@final
class SingleIntegrator:
    """``ds[pos[i]]/dt = a[i]``: one input per listed state dimension."""

    def __new__(cls, pos: Sequence[int]) -> Self: ...
    def eval(self, s: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...
    def step(self, s: ArrayLike, a: ArrayLike, dt: float) -> NDArray[np.float64]:
        """One Euler step ``s + dt (f(s) + g(s) a)``."""

@final
class DoubleIntegrator:
    """``ds[pos[i]]/dt = s[vel[i]]``, ``ds[vel[i]]/dt = a[i]``: one acceleration per position."""

    def __new__(cls, pos: Sequence[int], vel: Sequence[int]) -> Self: ...
    def eval(self, s: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...
    def step(self, s: ArrayLike, a: ArrayLike, dt: float) -> NDArray[np.float64]:
        """One Euler step ``s + dt (f(s) + g(s) a)``."""

@final
class AccelerationUnicycle:
    """A unicycle driven by forward acceleration and turn rate: state ``x, y, theta, v``."""

    def __new__(cls, x: int = 0, y: int = 1, theta: int = 2, v: int = 3) -> Self: ...
    def eval(self, s: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...
    def step(self, s: ArrayLike, a: ArrayLike, dt: float) -> NDArray[np.float64]:
        """One Euler step ``s + dt (f(s) + g(s) a)``."""

@final
class KinematicBicycle:
    """A kinematic bicycle about its rear axle: state ``x, y, theta, v``, inputs
    ``(a, tan delta)``; ``dtheta = v tan(delta) / wheelbase``."""

    def __new__(
        cls, wheelbase: float, x: int = 0, y: int = 1, theta: int = 2, v: int = 3
    ) -> Self: ...
    @property
    def wheelbase(self) -> float: ...
    def eval(self, s: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...
    def step(self, s: ArrayLike, a: ArrayLike, dt: float) -> NDArray[np.float64]:
        """One Euler step ``s + dt (f(s) + g(s) a)``."""

@final
class ThrustTurn:
    """A body pushed along its heading and turned at a commanded rate, with linear drag:
    state ``x, y, theta, vx, vy``, inputs ``(thrust, turn)`` (Safety-Gymnasium's Point)."""

    def __new__(
        cls,
        thrust: float,
        turn: float,
        drag: float,
        x: int = 0,
        y: int = 1,
        theta: int = 2,
        vx: int = 3,
        vy: int = 4,
    ) -> Self: ...
    @property
    def gains(self) -> tuple[float, float, float]: ...
    def eval(self, s: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...
    def step(self, s: ArrayLike, a: ArrayLike, dt: float) -> NDArray[np.float64]:
        """One Euler step ``s + dt (f(s) + g(s) a)``."""

@final
class ControlAffine:
    """A user's control-affine model ``ds/dt = f(s) + g(s) a`` given as callables; its
    structure (which dimensions the inputs move) is probed at construction."""

    def __new__(
        cls,
        f: Callable[[NDArray[np.float64]], ArrayLike] | ArrayLike,
        g: Callable[[NDArray[np.float64]], ArrayLike] | ArrayLike,
        *,
        state_dim: int,
        inputs: int,
        jacobian: Callable[[NDArray[np.float64]], ArrayLike] | ArrayLike | None = None,
        probe: ArrayLike | None = None,
    ) -> Self: ...
    def eval(self, s: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...
    def drift_jacobian(self, s: ArrayLike) -> NDArray[np.float64]:
        """The drift's Jacobian at ``s`` as the shield uses it (given, or by differences)."""
    def step(self, s: ArrayLike, a: ArrayLike, dt: float) -> NDArray[np.float64]:
        """One Euler step ``s + dt (f(s) + g(s) a)``."""
    @property
    def state_dim(self) -> int: ...
    @property
    def inputs(self) -> int: ...
    @property
    def actuated(self) -> list[int]: ...
    @property
    def integrated(self) -> list[int]: ...

Bound: TypeAlias = float | Sequence[float]
#: ``(lo, hi)``; a list ``[lo, hi]`` (as read back from JSON) is accepted too.
Bounds: TypeAlias = tuple[Bound, Bound] | Sequence[Bound]
Dynamics: TypeAlias = (
    Unicycle
    | SingleIntegrator
    | DoubleIntegrator
    | AccelerationUnicycle
    | KinematicBicycle
    | ThrustTurn
    | ControlAffine
)

@final
class FilterResult:
    """The outcome of one ``Shield.filter`` call."""

    @property
    def action(self) -> NDArray[np.float64]: ...
    @property
    def a_cbf(self) -> NDArray[np.float64]: ...
    @property
    def a_clf(self) -> NDArray[np.float64]: ...
    @property
    def delta(self) -> float: ...
    @property
    def status(self) -> Status: ...
    @property
    def slack(self) -> float: ...
    @property
    def gave_way(self) -> tuple[str, float] | None:
        """When the QP was relaxed: ``(name, slack)`` of the barrier whose row gave way the
        most (named as in ``barriers``), else None."""
    @property
    def goal(self) -> NDArray[np.float64] | None: ...
    @property
    def goal_unreachable(self) -> bool:
        """Whether this step's goal cannot be reached from the state, as far as the routing
        guidance can tell: it lies where the shield does not let the robot be (inside an
        avoided disc, outside a region the robot is kept in), or no way around the avoided
        discs leads to it. False without a routed goal."""
    @property
    def solver(self) -> Solver: ...
    @property
    def barriers(self) -> list[tuple[str, float]]: ...

@final
class FilterBatch:
    """The outcome of one ``Shield.filter_batch`` call: one row per state."""

    @property
    def action(self) -> NDArray[np.float64]: ...
    @property
    def a_cbf(self) -> NDArray[np.float64]: ...
    @property
    def a_clf(self) -> NDArray[np.float64]: ...
    @property
    def delta(self) -> NDArray[np.float64]: ...
    @property
    def slack(self) -> NDArray[np.float64]: ...
    @property
    def status(self) -> NDArray[np.uint8]:
        """``Status`` values."""
    @property
    def solver(self) -> NDArray[np.uint8]:
        """``Solver`` values."""
    @property
    def gave_way(self) -> list[tuple[str, float] | None]:
        """Per row, ``(name, slack)`` of the barrier that gave way, or None."""
    def __len__(self) -> int: ...

@final
class Shield:
    """The TL-CLF-CBF shield (paper Eq. 5D2)."""

    def __new__(
        cls,
        spec: Spec | Automaton,
        dynamics: Dynamics | None,
        *,
        alpha: float,
        c3: float,
        k: float,
        cbf_bounds: Bounds,
        clf_bounds: Bounds,
        action_bounds: Bounds | None = None,
        rl_bounds: Bounds | None = None,
        barriers: Sequence[BarrierLike] | Mapping[str, BarrierLike] | None = None,
        pos: Sequence[int] | None = None,
        use_cbf: bool = True,
        use_clf: bool = True,
        solver: Literal["auto", "active_set", "clarabel"] = "auto",
        slack_penalty: float | None = None,
        margin: float | None = None,
        alpha2: float | None = None,
        clf_gain: float | None = None,
        preserve_progress: bool = True,
        inputs: int | None = None,
        disturbance: Mapping[int, float] | None = None,
        route: bool = True,
        route_clearance: float | None = None,
        heading: int | None = None,
        speed: int | None = None,
        clf_round: tuple[int, int, float] | None = None,
        dt: float | None = None,
        give_way: Sequence[str] | None = None,
    ) -> Self:
        """``route`` aims the CLF at a target that leads around the discs the shield keeps
        the state out of (its avoid literals and ``Avoid`` barriers), re-planned every step, so
        that the CLF-CBF QP does not park the robot in front of an obstacle
        (``FilterResult.goal`` is that target); ``route_clearance`` is how far the route keeps
        from each disc, as a fraction of its radius (None: 0.2); ``heading`` is the state
        dimension of the heading that a turn input steers, for a custom model whose turn
        reaches the position only through it (None: the built-in model's), so that routing
        turns it towards the CLF's push; ``speed`` is the state dimension of the speed along
        that heading, for a custom model that turns only while moving, a car (None: the
        built-in model's, the ``KinematicBicycle``'s), so that routing asks for the speed a
        turn needs and backs up where driving on would only circle the target;
        ``clf_round=(i, j, radius)`` bounds the CLF's
        correction on inputs i, j by a circle, beside ``clf_bounds`` (held as the inscribed
        16-gon: up to 1.9% short of the radius), so that a bound meaning a speed does not
        depend on which way the world faces. ``inputs`` is the number of
        inputs m when ``dynamics`` is None and the bounds are scalars (a model gives m itself);
        ``slack_penalty`` prices barrier slack when the QP
        must be relaxed (None: 1e6); ``margin`` is what every barrier is kept above (> 0;
        None: 1e-6); ``rl_bounds`` is the range of the RL action: when given, a CBF box that
        cannot cancel every RL action plus every CLF correction is refused here, and an
        ``a_rl`` outside it is refused per call; ``alpha2`` is the second gain of the HOCBF
        rows that barriers of relative degree 2 need (an error when such a barrier exists
        and it is None); ``clf_gain`` is ``k`` of the second-order CLF ``|dp/dt + k (p -
        goal)|^2`` (None: 1); ``disturbance`` bounds the model's error per
        state dimension, ``{d: w_d}`` (the plant's ``ds_d/dt`` may differ from the model's by
        up to ``w_d``): each barrier row then holds for every such error (a robust CBF).
        ``pos`` is the state dimensions the CLF drives to the goal (None: the model's position,
        ``[0, 1]`` for a ``ControlAffine``). ``barriers`` states each barrier's side by its type
        (``Avoid(p)``, ``Inside(p)``). With a model, the layout is checked against it: a ``pos``
        or a ball over dimensions the model does not move, a centre read from dimensions it
        moves, and a ``drift`` on them are ``ShieldError``s that name the dimensions. ``dt``
        is the plant's time step when the action is held for ``dt`` and the state sampled
        after an Euler step of the model: the barrier rows then hold the sampled states
        (``h(s') >= (1 - alpha dt) h(s)``, docs/concepts/reliability.md), which needs
        ``alpha * dt <= 1`` and ``alpha2 * dt <= 1``; None: the continuous-time rows, which
        hold only as dt tends to 0. ``give_way`` is the order in which barriers give way
        when the QP cannot hold them all: names of barriers and atoms of the task, first named
        first; a barrier gives way only when relaxing every barrier named before it cannot
        restore feasibility, and the unnamed give way last (None: all at once, shared by
        the slack weights)."""
    def filter(
        self,
        s: ArrayLike,
        q: int,
        a_rl: ArrayLike,
        f: ArrayLike | None = None,
        g: ArrayLike | None = None,
        drift: ArrayLike | None = None,
    ) -> FilterResult:
        """One shield step at ``(s, q)`` for ``a_rl`` (at a ``Monitor``'s state:
        ``filter_monitor``)."""
    def problem(
        self,
        s: ArrayLike,
        q: int,
        a_rl: ArrayLike,
        f: ArrayLike | None = None,
        g: ArrayLike | None = None,
        drift: ArrayLike | None = None,
    ) -> dict[str, NDArray[np.float64]]:
        """The QP ``filter`` would solve at this step (before any relaxation): ``P_diag``,
        ``c``, ``G`` and ``h`` of ``min x'Px/2 + c'x  s.t.  G x <= h`` over ``x = [a_cbf |
        a_clf | d]``."""
    def filter_monitor(
        self,
        monitor: Monitor,
        a_rl: ArrayLike,
        f: ArrayLike | None = None,
        g: ArrayLike | None = None,
        drift: ArrayLike | None = None,
    ) -> FilterResult:
        """One shield step at the monitor's last state and FSA state."""
    def filter_batch(
        self,
        states: ArrayLike,
        qs: ArrayLike,
        a_rl: ArrayLike,
        drift: ArrayLike | None = None,
    ) -> FilterBatch:
        """A batch of steps (at a ``MonitorBatch``'s rows: ``filter_monitors``)."""
    def filter_monitors(
        self, monitors: MonitorBatch, a_rl: ArrayLike, drift: ArrayLike | None = None
    ) -> FilterBatch:
        """A batch of steps at the monitors' last states and FSA states."""
    def vjp_batch(
        self,
        states: ArrayLike,
        qs: ArrayLike,
        a_rl: ArrayLike,
        grad_action: ArrayLike,
        drift: ArrayLike | None = None,
        state_grad: bool = True,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64] | None, NDArray[np.uint8]]:
        """``(dL/da_rl, dL/dstates or None, flags)`` of ``filter_batch`` for ``grad_action``
        ``= dL/daction`` (B, m); flags are ``tlshield.GradFlag`` bits."""
    def jacobian_batch(
        self,
        states: ArrayLike,
        qs: ArrayLike,
        a_rl: ArrayLike,
        drift: ArrayLike | None = None,
        state_grad: bool = True,
    ) -> tuple[
        NDArray[np.float64], NDArray[np.float64], NDArray[np.float64] | None, NDArray[np.uint8]
    ]:
        """``(action, d action/d a_rl (B, m, m), d action/d states (B, m, n) or None, flags)``
        of ``filter_batch`` in one pass."""
    def barrier_values(self, s: ArrayLike) -> dict[str, float]:
        """Every user barrier's value ``h(s)`` by name (> 0 while it holds)."""
    @property
    def num_inputs(self) -> int: ...
    @property
    def routes(self) -> bool:
        """Whether the CLF's target is routed around the discs the shield keeps out."""
    @property
    def automaton(self) -> Automaton: ...

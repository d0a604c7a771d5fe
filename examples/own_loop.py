import numpy as np

import tlshield

# The paper's task: reach g1 or g2, then g3, staying in the channel |x - y| < 1.5 until g3.
goals = [
    tlshield.Ball(pos=[0, 1], radius=0.5, center_dims=[3 + 2 * k, 4 + 2 * k]) for k in (0, 1, 2)
]
c = np.zeros(13)
c[[0, 1]] = [1, -1]
spec = tlshield.Spec(
    "(F g1 | F g2) & F g3 & (!g3 U (g1 | g2)) & ((c1 & c2) U g3)",
    {"g1": goals[0], "g2": goals[1], "g3": goals[2],
     "c1": tlshield.Halfspace(c, 1.5), "c2": tlshield.Halfspace(-c, 1.5)},
    exclusive=[["g1", "g2", "g3"]],  # the goal discs never overlap
)  # fmt: skip
shield = tlshield.Shield(spec, tlshield.Unicycle(eps=0.1), alpha=2.0, c3=1.0, k=1e4,
                         cbf_bounds=(-6.0, 6.0), clf_bounds=(-0.5, 0.5),
                         dt=0.1)  # the plant's step below: rows hold its samples  # fmt: skip
monitor = tlshield.Monitor(shield.automaton, c_r=1.0, trap_penalty=-30.0)
s = np.zeros(13)  # the robot at the origin, heading 0; then the centres of g1, g2, g3
s[3:9] = [2.0, 2.0, 4.0, 3.5, 8.0, 8.0]
task, rng, steps = monitor.reset(s), np.random.default_rng(0), 0
while not (task.accepted or task.trapped) and steps < 500:
    a_rl = rng.normal(0.0, 0.1, size=2)  # your policy
    out = shield.filter_monitor(monitor, a_rl)  # call 1: the CLF-CBF QP at (s, q)
    (v, w), dt = out.action, 0.1  # your plant: a unicycle, one Euler step
    s[:3] += dt * np.array([v * np.cos(s[2]), v * np.sin(s[2]), w])
    task, steps = monitor.advance(s), steps + 1  # call 2: q, reward, accepted, trapped, goal
print(f"{steps} steps: accepted={task.accepted}, trapped={task.trapped}")

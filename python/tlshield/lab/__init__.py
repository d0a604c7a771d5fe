"""tlshield's lab: the experiment machinery that ``make run``, the benchmarks and the learning
studies use, kept apart from the library (``tlshield`` itself: the core, ``envs``,
``wrappers``, ``tracking``, ``vector``, ``sb3`` and ``torch``, which is what a user's own code
imports).

Here: the command line (:mod:`~tlshield.lab.cli`, ``python -m tlshield``), PPO training and
its callbacks and presets (:mod:`~tlshield.lab.training`, :mod:`~tlshield.lab.callbacks`,
:mod:`~tlshield.lab.presets`, :mod:`~tlshield.lab.policies`), evaluation and the run folders
it reads (:mod:`~tlshield.lab.evaluation`, :mod:`~tlshield.lab.runs`,
:mod:`~tlshield.lab.saved`, :mod:`~tlshield.lab.measures`, :mod:`~tlshield.lab.seeds`), sweeps
on Ray (:mod:`~tlshield.lab.cluster`, :mod:`~tlshield.lab.tune`,
:mod:`~tlshield.lab.settings`), the benchmarks (:mod:`~tlshield.lab.benchmark`,
:mod:`~tlshield.lab.benchmark_safety_gym`) and the report (:mod:`~tlshield.lab.report`,
:mod:`~tlshield.lab.plots`). The library never imports the lab; ``import tlshield`` loads none
of it. The 0.1 names of these modules (top-level ``training``, ``plots``, ...) were removed in
0.3.
"""

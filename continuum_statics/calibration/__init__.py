"""Calibration: robot-file parameters fitted to measurements of a real robot.

One library for both data kinds: recorded runs (cable lengths and a tracked tip, replayed
through ``solve_lengths``: :func:`runs.calibrate_run`) and static tip-load rows
(:func:`tip_loads.calibrate_tip_loads`). Modules, one idea each:

- :mod:`.parameters`: the fit names, the search vector, the candidate robot, the E/G rule
- :mod:`.recorded_run`: reading runs (CSV with a column map, rosbag2)
- :mod:`.replay`: a run replayed through the model, Kabsch registration, error statistics
- :mod:`.run_model`: a run's residuals of a search vector
- :mod:`.fit`: the pattern-rotation scan and the least-squares fit
- :mod:`.pool`: the Jacobian's worker processes (forked; serial fallback)
- :mod:`.summary`: the summary schema (m), 1-sigma, notes, the file header
- :mod:`.robot_writer`: the calibrated robot file
- :mod:`.error_budget`: repeatability floor, smooth baselines and the model, side by side
- :mod:`.selection`: candidate fit names kept by cross-validation inside the run
- :mod:`.runs`, :mod:`.tip_loads`: the two calibrations, from files to the summary
"""

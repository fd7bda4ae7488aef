# The two commands of README.md: `make demo` (main job) and `make test` (whole suite).
# Both create .venv on first use and reuse it afterwards.
.PHONY: venv venv-jazzy demo test test-core docs test-jazzy bench bench-nodes bench-nodes-noisy bench-drivers bench-tendons bench-calibration bench-load lint clean fuzz soak

venv:
	@scripts/setup_venv.sh

demo: venv
	scripts/ros_env.sh .venv/bin/python -m continuum_statics demo

# The suite in two tiers: the fast one (no DDS, no process: physics, decisions, drivers against
# emulators, tools in-process) on both cores, then the `ros` tier (nodes over DDS, subprocesses;
# scripts/ros_tier.sh); each prints its ten slowest tests.
test: venv
	scripts/install_browser.sh
	scripts/ros_env.sh --private .venv/bin/python -m pytest -q -n 2 -m "not ros" --durations=10 test
	scripts/ros_tier.sh .venv/bin/python

# The newcomer's first command: the fast tier alone (test/core, control, calibration, drivers,
# tools, package without DDS or processes), in about two minutes on two cores.
test-core: venv
	scripts/ros_env.sh --private .venv/bin/python -m pytest -q -n 2 -m "not ros" --durations=10 test

# The documentation (doc/, Sphinx + MyST, what rosdoc2 builds) into build/doc/index.html; warnings
# (a broken internal link or anchor, a bad docstring) are errors. `make test` builds it too
# (test/package/test_docs_build.py).
docs: venv
	.venv/bin/python -m sphinx -E -W --keep-going -q -b html doc build/doc
	@echo "docs: build/doc/index.html"

# The second route: the ROS-facing tests on ROS 2 Jazzy wheels (requirements-jazzy.txt,
# .venv-jazzy): the fast tests of nodes, tools and package, and the `ros` tier. The fast tests of
# core/, control/, calibration/ and drivers/ run on Kilted only: those modules import no ROS
# (test_layer_contracts) and both venvs pin the same non-ROS packages (test_tools_routes), so
# their results cannot depend on the distribution. So do the `ros` tests whose subject is not
# ROS: the cold-start ones (test_cold_start.py: numba's compile and cache from an empty cache,
# 190-330 s of a worker on a 2-GHz machine) and the `alone` ones (figures of a quiet machine:
# the load estimate under friction, the browser's page); the nodes they start are the nodes the
# other `ros` tests run on both.
JAZZY_FAST = test/nodes test/tools test/package
JAZZY_ROS_SKIP = --deselect test/core/test_cold_start.py
venv-jazzy:
	@VENV=.venv-jazzy REQUIREMENTS=requirements-jazzy.txt scripts/setup_venv.sh

test-jazzy: venv venv-jazzy
	scripts/install_browser.sh
	scripts/ros_env.sh --private .venv-jazzy/bin/python -m pytest -q -n 2 -m "not ros" --durations=10 $(JAZZY_FAST)
	scripts/ros_tier.sh --no-alone .venv-jazzy/bin/python $(JAZZY_ROS_SKIP)

bench: venv
	scripts/ros_env.sh .venv/bin/python -m continuum_statics bench
	.venv/bin/python -m benchmarks.bench_release
	.venv/bin/python -m benchmarks.bench_tendons
	.venv/bin/python -m benchmarks.bench_load
	.venv/bin/python -m benchmarks.bench_noisy
	.venv/bin/python -m benchmarks.bench_fusion
	.venv/bin/python -m benchmarks.bench_mismatch
	.venv/bin/python -m benchmarks.bench_dynamics
	.venv/bin/python -m benchmarks.bench_obstacles

bench-nodes: venv
	scripts/ros_env.sh --private .venv/bin/python -m continuum_statics bench --nodes

# statics at 1 kHz fed lengths with 20 um encoder noise, on every example robot with cables
bench-nodes-noisy: venv
	for robot in tendon_robot tendon_robot_real_tendons two_section_robot three_section_robot \
	        three_section_robot_real_tendons ftdcr_v6_robot ftdcr_v6_calibrated; do \
	    scripts/ros_env.sh --private .venv/bin/python -m continuum_statics bench --nodes \
	        --skip-goals --noise 2e-5 --robot config/$$robot.yaml || exit 1; done

# Dynamixel backend against the Protocol 2.0 emulator on a simulated 1 Mbps wire: sync write +
# sync read cycle and the highest cable_driver publish_rate, for 4 and 9 servos.
bench-drivers: venv
	scripts/ros_env.sh --private .venv/bin/python -m benchmarks.driver_bench

# Differential fuzzing of the raw CDR JointState parser against rclpy, FUZZ_EXAMPLES cases per
# test (random each run; `make test` runs 1500 per test, derandomized).
fuzz: venv
	FUZZ_EXAMPLES=$${FUZZ_EXAMPLES:-50000} scripts/ros_env.sh --private .venv/bin/python -m pytest \
	    -q -p no:cacheprovider test/nodes/test_fuzz_joint_state.py

# Not in CI: bringup at 1 kHz with a random reachable goal every 2 s for 10 minutes; prints goals
# reached/answered, RSS at start and end, warnings. Options: make soak SOAK_ARGS='--minutes 3'.
# A lab's normal use instead (dynamics, a noisy tracker with dropouts, move_tip and tip_goal goals
# with cancels and pre-emptions, one restart): make soak SOAK_ARGS='--normal-use'.
soak: venv
	scripts/ros_env.sh --private .venv/bin/python -m benchmarks.soak $(SOAK_ARGS)

lint: venv
	.venv/bin/ruff check .

clean:
	rm -rf .venv .venv-jazzy build install log *.egg-info

# Real tendons: solve_lengths warm/cold beside SciPy.
bench-load: venv
	.venv/bin/python -m benchmarks.bench_load --plot doc/images/tip_load_noise.png

bench-tendons: venv
	.venv/bin/python -m benchmarks.bench_tendons

# The v6 calibration: replay cost, the default fit (and on a 1600-row run), train and held-out
# RMS, the error budget (about two minutes); CANDIDATES="cable_stiffness section_length" adds
# their cross-validation inside the training run (minutes each).
bench-calibration: venv
	.venv/bin/python -m benchmarks.bench_calibration --long $(if $(CANDIDATES),--select $(CANDIDATES))

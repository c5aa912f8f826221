"""In-process flight speed: where a 4 ms control step of case 1 spends its time.

    python benchmarks/bench_inproc.py [--case 1] [--controller gs-shif] [--duration 40]
                                      [--profile] [--top 25]

Flies the case in-process (``run_scenario``, no observers, as ``bench_sitl.py``'s reference
line) after a short warm-up flight (the compiled kernels loaded), and prints the real-time
factor, the runner's per-stage wall time per control step (``RunResult.timing_s``: physics,
HIL encode/decode, autopilot, metrics + the runner's bookkeeping) and the load average. With
``--profile`` it flies once more under cProfile and prints the Python function calls per step
and the ``--top`` functions by own time (a numba kernel is one call: its time is its own).

Measured (2026-12-02, 2 cores shared by eight engineers, load average 18-26, so absolute
times are 3-5x an idle machine's; ratios are what to read):

- per step, case 1 gs-shif (four runs): autopilot 57-64 %, physics 19-29 % (its RK4 kernel,
  4 x 1 kHz, most of it), HIL encode/decode 5.5-7 %, metrics 7-10 %, the runner's loop 1-2 %;
- 134 Python function calls per control step on the base tree, 121 on this branch (cProfile),
  of which the autopilot makes ~110;
- own time by function (sampled with py-spy, the flight only; a kernel's time is its
  caller's): ``Vehicle.step`` 15.5 % (the RK4 kernel), ``ActiveSetAllocator.allocate``
  15.0 % (its kernel, and unboxing its 29 arguments: a no-op kernel of the same arguments
  costs 45 % of the real call), ``_solved`` 8.3 % (``B @ u``, the result and the
  statistics), ``ScheduledPPIDController.update`` 5.9 %, ``run_scenario`` 5.8 %,
  ``HilRoundTrip`` 5.7 %, ``OutputStage.allocate`` 3.9 %, ``StateEstimate.update`` 3.7 %,
  ``MetricsAccumulator.add_step`` 3.2 % (before its kernel: 37 lines of Python per step),
  ``wire_commands`` 3.2 %, ``Commander.update_mode`` 2.6 %, the outer loops (``update``,
  ``_position_hold``, ``_outer_mc``, ``_outer_fw``, altitude holds) 8 %, the navigator,
  modes, arming, saturation tracking and the result objects the remaining ~10 %.

What was built on this (branch inproc-10), every flight bit-identical
(``command_digest.py``: fad6f718..., 2be6f774..., 1a23074e... unchanged on the aerodynamics
of that time, dbd91a71..., 121a7434..., e937b801... since the sideways-flow fix; every metric of
cases 0, 1, 2, with and without an observer, equal to the last digit):

- the metrics' per-sample arithmetic in one numba kernel on a flat state and a ring buffer
  (``vtolftc/telemetry/metrics_kernel.py``), no Python object per sample;
- the active-set allocator's own eleven arrays packed into one workspace
  (``_allocate_step_packed``): 13 array arguments per call instead of 24.

Measured A/B in one process (thread CPU time, the 9,750 allocations and 10,000 metric
samples of one case-1 flight replayed through the base code and this branch's, 7 interleaved
pairs, load average 19 on 2 cores): ``ActiveSetAllocator.allocate`` 15.5 -> 14.6 us per call
(x0.94), ``MetricsAccumulator.add_step`` 3.17 -> 2.69 us (x0.89; the kernel's call itself is
0.6-0.7 us, the rest is the Python wrapper's argument checks). Together ~1.4 us of a
~70 us step (thread CPU time per step of the whole flight, same load): ~2 %, below the
+-10 % spread of whole-flight timings on this loaded machine (farm-bench, 5 pairs of
40 s flights, base vs branch: median ratio of thread CPU time 0.97). A reused float32 buffer
for the wire rounding measured 1.14 vs 1.12 us and was reverted.

Issue 24, branch compile-11 (2026-12-02): fewer Python calls and fewer compiled-call
arguments per control step, every flight bit-identical (``command_digest.py``: dbd91a71...,
121a7434..., e937b801... unchanged after each commit; each fast path has a test against the
code it replaces, equal to the last bit on random inputs, ``tests/test_inproc_fastpaths.py``):

- the output stage calls ``ActiveSetAllocator.allocate_trusted`` (no argument checks, no
  ``AllocationResult`` on a converged step, the saturation tracking inlined) and its kernel
  ``_allocate_step_trusted`` takes 8 arrays instead of 13 (each array argument of a numba
  call costs ~0.15-0.2 us here to type-check and unbox: measured with no-op kernels of 1 and
  13 arrays, 0.27 vs 2.2 us a call at load 17);
- the attitude stage steps ``scheduled_ppid3_step`` directly on the controller's arrays
  (``ScheduledPPIDController.kernel_arrays``), no ``update`` / ``_f64`` / copy;
- ``StateEstimate.update`` computes the Euler angles inline (``quat_to_euler``'s expressions);
- the commander calls the auto-disarm only when it can act (``ArmingMonitor.airborne``), and
  ``drain_events`` / ``hover_recoverable`` only when they have something to do;
- ``Vehicle.step`` takes the commands and flies the batch in one compiled call
  (``_take_and_step``); the runner takes the crash flag from ``add_step``.

Python function calls per control step (cProfile, ``--profile``): 121 -> 96. Measured A/B
(case 1 gs-shif, 40 s, thread CPU time per control step, interleaved pairs of processes
main/branch, 2 flights each, in one script): 5 pairs at load average 27-30 on 2 cores: main
53.4 us, branch 45.0 us (medians), ratio branch/main per pair 0.68-1.07, median 0.91; 6 pairs
at load 16-18: main 49.1 us, branch 39.4 us, ratio 0.74-0.97, median 0.80 (wall time 0.81;
real time 39x -> 49x at that load). All 11 pairs: median ratio 0.80, i.e. ~1.25x faster.
At this load the figures are 2-3x an idle core's; the ratio is what to read, and its spread
says +-15 %. One run of this script afterwards (load 17): 61x real time, 65 us per step,
autopilot 51 %, physics 32 %, metrics 12 %, HIL codec 4 %.

Why 150x (26 us per step in all) is still not reached. The issue's 57-61x per core (idle)
divided by the ratio above (0.80) is ~71-76x (an estimate: no idle core to measure on). What a step
still does after this branch (cProfile, case 1): 96 calls, of which ~27 Python functions
(runner loop and ``HilRoundTrip``; ``Autopilot.step``, ``StateEstimate.update``,
``Commander.update_mode`` with ``ModeMachine.update`` and ``Navigator.update``, the outer
loops' 4-6 (``update``, ``aero_estimate``, ``_outer_mc`` or ``_outer_fw``, an altitude hold,
``_position_hold``, ``pusher_max_force``), ``AttitudeStage.update``, ``OutputStage.allocate``
and ``allocate_trusted``; ``metrics_inputs``, ``add_step``, ``wire_commands``,
``Vehicle.step``) and ~70 builtins (16 ``isfinite``, 16 ``min``/``max``, 7 ``tolist``, 7
``perf_counter``, ~11 trigonometric); and 5 compiled calls (HIL round trip, P-PID,
allocation, metrics, vehicle) with 33 array arguments, ~5-6 us of unboxing per step at this
load by ``bench_dispatch.py``'s figures. Per-stage wall time at load 26 (``bench_inproc``):
physics 54 us (36 %), autopilot 73 us (49 %), metrics 12 us (8 %), HIL codec 10 us (6 %).
The physics kernel alone is ~13 us per step on an idle core (4 RK4 steps of the 6-DOF model;
bit-identical flights forbid a cheaper integrator), which leaves ~13 us for everything
else; the Python that remains is spread thin (no function left costs more than ~2 % of the
step), so removing calls one by one has reached diminishing returns. What would take it
there: the autopilot's continuous part (estimate, outer loops with their altitude and
airspeed holds, position hold, attitude, allocation and saturation tracking) as one compiled
function over one flat state array, with Python only for mode changes, commands, the
navigator's rare decisions and events; and the runner's per-step work (HIL round trip,
metrics, wire rounding, vehicle step) fused into one compiled call: 1-2 dispatches of a few
array arguments per step instead of 5 of 33 plus ~27 Python functions. That is a rewrite of
the outer loops, the altitude holds and the navigator's per-step guidance (~1,500 lines)
whose every branch must be re-proved bit-identical. One trap measured on this machine
(200,000 random pairs): numba's ``math.atan2``, ``sin``, ``cos``, ``asin`` and ``sqrt`` give
CPython's bits (both call the C library), ``math.hypot`` differs in 1,129 of them (CPython
3.11 computes it with its own algorithm), so the position hold's ``hypot`` would need a port
of CPython's to stay bit-identical.

Issue 24, branch inproc-12 (2026-12-02, 2 cores shared with 3-4 other engineers, load 4-10).

Where a control step goes (py-spy, 2,000 samples/s, four 60 s flights of case 1 gs-shif,
the samples of the flights only, a compiled kernel's time counted on its calling line;
load ~4-6), share of the step: ``Vehicle.step`` 29.6 % (its RK4 kernel 28.3 %);
``OutputStage.allocate`` 24.0 %, of which ``allocate_trusted`` 16.7 % (the active-set
kernel's call 12.1 %, ``B @ u`` 2.7 %) and the output stage's own Python 7.3 %;
``OuterLoops.update`` 15.0 % (``_outer_mc`` 4.6, ``_outer_fw`` 4.1, ``_position_hold``
2.4, the altitude holds 2.2, ``pusher_max_force`` 1.1, ``aero_estimate`` 0.8, degraded
lift 0.7); ``AttitudeStage.update`` 6.6 % (the P-PID kernel's call 5.0 %); metrics
``add_step`` 4.4 %; ``HilRoundTrip`` 4.3 %; ``Commander.update_mode`` 3.7 % (with
``ModeMachine.update`` 0.6, ``Navigator.update`` 1.0); ``StateEstimate.update`` 3.7 %;
``wire_commands`` 2.2 %; ``metrics_inputs`` 0.8 %; the runner loop's own lines ~3 %. The
compiled numerical work (physics, QP, P-PID, metrics, HIL codec kernels) is about half of
the step, the Python around it the other half, spread over ~20 functions none above 7 %.
This run's per-stage wall time (load 8.6, 60 s, 68.9 us per step): physics 21.2 us,
autopilot 36.6, metrics 5.9, HIL codec 3.6, runner 0.7.

Built (every flight bit-identical, ``command_digest.py`` dbd91a71..., 121a7434...,
e937b801... after each commit; tests in ``tests/test_inproc_fastpaths.py``):

- ``dynamics.derivatives`` reads the rotation as nine scalars (``quat_to_dcm_entries``)
  instead of allocating a 3x3 array at each of its 17 evaluations per control step;
- the first RK4 stage of a control step takes the rigid-body rows of the previous step's
  final evaluation (the one that leaves ``fm`` on the final state; those rows do not depend
  on the commands) and computes only the actuator rows (``actuator_rates``): 16
  evaluations per step instead of 17 (``step_n_memo``; the memo is used only when the
  state, effectiveness, wind and physics switches are bit for bit those of that
  evaluation, cleared on a new airframe; hit on 9,996 of 9,998 fused steps of case 1).

Measured: the physics kernel on the 14,998 commands of one recorded 60 s case-1 flight,
main's kernel and this branch's in one process (copies compiled without cache), 15
interleaved pairs, thread CPU time, load 8.8: 10.99 -> 9.62 us per control step (medians;
pair ratio median 0.860, range 0.72-1.02), the same bits. Whole flights (60 s case 1, main
and branch processes alternated, 8 pairs, thread CPU per step, load 6.5-7.5): main
35.7-47.2 us, branch 32.5-46.7 us, pair ratios 0.70-1.17 (median ~0.99): the ~1.4 us gained
(~4 % of a step) is below this machine's whole-flight noise at that load. Tried and
dropped: ``derivatives`` inlined into ``step_n`` by numba (``inline='always'``): another
~4 % of the kernel (12.7 -> 12.1 us, same bits) but its compilation 6 -> 19 s CPU on a
fresh cache (the SITL vehicle's warm-up compiles it); the five RK4 work arrays of a call
preallocated: no measurable change.

Why 150x (26.7 us per step) is not reached, and the decision. Main measured 32.9 us of
thread CPU per step at load 3.8 (121x; the lead's idle figure 36 us wall): the step must
lose ~6-7 us, ~20 %. The physics gains here are ~1.4 us. What is left is (a) compiled
numerical work that a bit-identical flight must keep (the RK4 model ~9.6 us, the QP ~4 us,
the P-PID, metrics and codec kernels ~3 us) and (b) ~15 us of Python and dispatch spread
thin: the outer loops (~5 us), the output stage's bookkeeping (~2.5 us), estimate,
commander, navigator, metrics and codec wrappers (~1-1.5 us each). Reaching 26 us takes (b)
down to ~8 us, i.e. the outer loops with their altitude and airspeed holds, the position
hold, the estimate and the output stage's bookkeeping compiled into the existing kernels
(one call per step on one flat state array), Python left with the mode logic, commands and
the navigator's decisions. Of the two routes, compiling the autopilot's continuous part is
the simpler one: a batched campaign engine (many scenarios stepped together) needs the same
per-step code in array form anyway, and its scenarios leave each other at the first
diverging mode change or fault (different times per scenario), so each batch lane would
still need the per-scenario Python it was meant to remove; the campaign's overhead is
already ~2 % (the pool's rate is the flight's rate), so the 300 scenarios/min target is the
per-core target again (0.40 s per 60 s flight = 26.7 us per step). Not done this session:
that rewrite (~1,000 lines whose every branch must be re-proved bit-identical, including a
port of CPython's ``math.hypot`` for the position hold, see above).

Issue 24, branch inproc-13 (2026-12-03, 2 cores shared with 4 other engineers, load 11-20).

Case 1 and the campaign's 60 s scenario, step for step (one process, the runs interleaved,
thread CPU time per control step, 3 runs each, load 12.7): case 1 gs-shif 40 s 37.5 us
(median; 32.6-38.1), the campaign's first three scenarios (10 % loss of rotor 1a at 40 s in
cruise, gs-shif / shif / lqr) 37.9, 35.1 and 36.5 us. The campaign's step is not slower:
active-set iterations per step 1.015-1.018 (case 1: 1.019), saturated steps 0.1 % (case 1:
0.2 %), the degraded-lift monitor 0.13 calls per step (case 1: 0.20); what differs is the mix
(cProfile, calls per step): 54 % of its steps are fixed-wing (``_outer_fw``, the fixed-wing
altitude hold, ``pusher_max_force``, the reserve allocator) against 30 % in 40 s of case 1,
whose multicopter steps cost ``_outer_mc`` + ``_position_hold`` + the multicopter altitude
hold instead, about the same. The lead's 130x vs 136-141x (0.46 s per 60 s) is
``bench_campaign``'s mean over the three controllers' wall times, within the +-10 % spread of
single runs; the campaign needs the same per-step cut as case 1.

Built (every flight bit-identical, ``command_digest.py`` dbd91a71..., 121a7434...,
e937b801... after each commit; tests in ``tests/test_inproc_fastpaths.py``, each checked to
fail under mutations of the new code):

- the output stage's ``allocate -> allocate_trusted -> kernel`` with numpy's ``B @ u``, two
  ``tolist``, the flag lists and the command copy in Python became one compiled call
  (``ActiveSetAllocator.allocate_tracked``, kernel ``_allocate_step_tracked``): the solve,
  ``B u`` by ``np.dot`` (the BLAS ``dgemv`` numpy's ``@`` calls: equal bits on 20,000
  random products here, where a plain loop differs in 19,596: the test pins it), the
  saturation mask (``allocation.shortfall_mask``, now also the non-trusted path's) and the
  command written into the output stage's array; the flag lists come from a table;
- the vehicle's ``x``, ``u``, ``eff``, ``wind``, ``fm`` and RK4 memo are views of one float
  workspace (copy and pickle relink them): its control-step call takes 5 arrays instead of
  10 (``_take_and_step_packed``);
- the wire's float32 rounding of the commands happens in that same call
  (``Vehicle.step(u, n, wire=True)``, ``protocols.hil.wire_round``) instead of
  ``wire_commands``' numpy round trip (``timeit`` at load 13: 3-6 us a call against 0.4-0.7
  us for a plain ``u.copy()``).

Python function calls per control step (cProfile, ``--profile``): 96 -> 90; array arguments
of the compiled calls per step: vehicle 10 -> 5, allocation 8 -> 9 (``u_out``).

Measured A/B (case 1 gs-shif 40 s; main = /work/main's tree, branch = this one; processes
alternated main/branch, each a warm-up flight then 2 flights, the faster one's thread CPU
time per control step; 8 pairs at load 17-20): main 29.4-39.6 us (median 32.2), branch
27.4-35.4 us (median 29.9); ratio branch/main per pair 0.76-1.03, median 0.935. The
campaign's first scenario (``bench_campaign``'s spec, 60 s, gs-shif, the same way, 6 pairs at
load 14-20): main 32.3-36.6 us (median 34.2), branch 29.7-35.0 us (median 31.6), ratio
0.84-1.04, median 0.93: on the lead's idle figures ~0.43 s per 60 s scenario (~140x), a
2-core pool at ~265 scenarios/min (248.8 / 0.93; not run through ``bench_campaign`` here).

Why 150x (26.7 us per step) and 300 scenarios/min (~22-24 us per step) are not reached: the
cut here is ~7 % (~2 us of the lead's idle 28.3-29.4 us: ~26.5-27.5 us per step at idle by
that ratio, around the 150x line but not the campaign's 22-24 us). What is left per step
(cProfile calls above, the py-spy shares of inproc-12): the physics kernel (~8 us idle, 4 RK4
steps; a cheaper integrator changes the bits), the QP (~3-4 us), the P-PID, metrics and codec
kernels (~2-3 us), and ~12-13 us of Python spread over ~20 functions none above ~7 % of the
step: ``StateEstimate.update`` (four ``tolist``, 13 ``isfinite``), the outer loops
(``update``, ``_outer_mc`` / ``_outer_fw``, ``_position_hold``, an altitude hold,
``aero_estimate``, ``pusher_max_force``: ~5 us), ``Autopilot.step``, ``Commander.update_mode``
with the mode machine and the navigator (~2 us), the attitude stage's wrapper, the output
stage's bookkeeping (grid key, hand-over, limits key, status), ``metrics_inputs`` +
``add_step``, ``HilRoundTrip`` and the runner loop. The next ~5-7 us are only in compiling
that continuous part (estimate, outer loops with the altitude and airspeed holds, position
hold, attitude and allocation) into one call on one flat state, Python keeping the mode
logic, commands and the navigator's decisions: the route the previous rounds chose, over a
batched campaign engine (its lanes would still run each scenario's Python between diverging
mode changes and faults). Not done this session: that rewrite, with a port of CPython's
``math.hypot`` for the position hold.

Issue 24, branch inproc-14 (2026-12-03, 2 cores shared with 2 other engineers, load 5-18).
Start (main, this branch's base, load 0.1, idle): ``bench_inproc`` case 1 143.2x, 27.9 us per
step wall (physics 8.2, codec 1.7, autopilot 15.5, metrics 1.9, runner 0.2). py-spy (2,000/s,
six 60 s flights): vehicle kernel 27 %, allocation kernel call 14 %, P-PID call 5.7 %, outer
loops 14.6 % in all, estimate 4.8 %, codec 5.5 %, metrics 4.8 %. Measured here (thread CPU,
one process, interleaved, load ~14): a numba call costs ~0.05 us per array argument, ~0.03
per bool, ~0.01 per float (no-op kernels: 1 array 0.14 us, 10 arrays 0.57 us); a
``min(max(x, lo), hi)`` 0.21 us against 0.04 us as two comparisons. Built (every flight
bit-identical, ``command_digest.py`` dbd91a71..., 121a7434..., e937b801... after each commit;
tests in ``tests/test_inproc_fastpaths.py`` and ``test_metrics_kernel.py``, each checked to
fail under a mutation):

- the P-PID step on two packed arrays and one int (``scheduled_ppid3_step_packed``: the
  schedule's tables in ``GainSchedule.kernel_packed``, the controller's gains, state,
  constants and output views of one workspace, relinked on copy and unpickle; the
  saturation flags as the output stage's mask ``OutputStage.sat_mask``): 17 arguments
  (10 arrays, 6 bools) -> 7 (5 arrays); the call with its argument conversions 1.88 ->
  1.40 us (9 interleaved pairs, load 14);
- the allocator's workspace, limits and command buffer as views of one array: 9 -> 7 array
  arguments (``_allocate_step_tracked_packed``), 5.24 -> 5.16 us a call;
- the per-step builtins ``min`` / ``max`` of the outer loops, altitude holds and attitude
  stage (16 calls per step) written as comparisons with the builtins' own rule
  (``max(a, b)`` = ``b if b > a else a``: the same result for NaN and signed zeros);
- the metrics kernel answers "crashed" itself (returns 2), no read-back of its state;
  ``StateEstimate.euler`` hands the metrics the step's angles without ``tuple(att.tolist())``.
- tried and dropped: the estimate's 13 ``math.isfinite`` as one sum of ``x - x`` terms
  (1.30 vs 1.32 us a call: no gain).

Python function calls per step (cProfile): 90 -> 73. Whole flights (main's tree and this
branch's in alternate processes, each a warm-up then two runs, the faster one's thread CPU
per step; 24 pairs at load 10.5-18): case 1 gs-shif 40 s main 32.7 us, branch 29.2 us
(medians), pair ratio median 0.941 (0.71-1.37, 18 of 24 pairs below 1); the campaign's first
scenario (60 s, ``bench_campaign``'s spec) main 33.9, branch 29.1 us, ratio median 0.881
(0.73-1.26, 19 of 24). On the idle start figure (27.9 us) 0.941 gives ~26.3 us per step,
~152x: over the line by ~2 %, less than the pairs' spread at this load (no idle machine to
confirm it on). The campaign's 60 s scenario at 0.881 of inproc-13's idle ~0.43 s is
~0.38 s, ~315 scenarios/min on 2 cores before the pool's 1-3 %: an estimate from loaded
ratios, not a measured idle pool run (``bench_campaign`` not run here). What is left is as
inproc-13 wrote: the vehicle kernel (~8 us), the QP (~4-5 us), and ~11 us of Python spread
over ~20 functions; the next step is still the compiled continuous part of the outer loops.

The lead's idle check after merging inproc-14 (main 998fee6, 2026-12-03 07:37 UTC,
load 0.7, no other job): ``bench_inproc`` case 1, 4 runs back to back: 160.6x, 155.4x, 156.6x,
161.0x (24.8-25.7 us per step); >= 150x real time per core is reached on this idle machine
(the same command on the base an hour earlier, load 0.0-0.1: 132.6-148.2x, 27.0-30.2 us; a
second set of 3 runs minutes later gave 142.4 / 151.6 / 146.6x for gs-shif / shif / lqr: the
host's own noise is +-5 %). ``bench_campaign.py --jobs 2 --scenarios 24 --no-dask`` in the
same minute: 256.1 scenarios/min, overhead +3.6 %, the warm 60 s scenario 0.49 s (mean of
3; the pool's workers took 0.47 s per scenario against 0.45 s of flight). The campaign's first three
scenarios (gs-shif, shif, lqr), 6 interleaved flights each in one process, thread CPU, load
~2.9 with a CI run beside: medians 0.393, 0.394, 0.423 s per 60 s flight (26-28 us per step;
cProfile: the same calls per step for every controller; a first set at load 0.7 spread
0.39-0.55 s, the host's noise). 300 scenarios/min needs <= 0.40 s per flight with both
workers running at once: not reached (256.1/min measured).

Issue 24, branch inproc-15 (2026-12-03, 2 cores shared with 2 other engineers running CPU
burners at times: load 8-13 throughout). The outer loops' continuous part compiled, Python
keeping the mode logic, the navigator and the front/back transitions (every flight
bit-identical, ``command_digest.py`` dbd91a71..., 121a7434..., e937b801... after each
commit; each kernel tested bit for bit against the Python it replaced, copied into
``tests/test_inproc_fastpaths.py``, each test checked to fail under a mutation):

- ``StateEstimate.update`` is one call (``estimate.estimate_step``: the 13 finiteness
  checks, the Euler angles, the body-axis velocity x and z the outer loops used to compute
  from ``ql`` / ``vel``, altitude and climb rate into a 7-float workspace, ``att`` a view of
  it); in one process on 5,000 recorded-like samples, 15 interleaved pairs, thread CPU, load
  9.7: 3.06 -> 1.48 us per step (update + the outer loops' body velocity);
- the outer loops' aerodynamics of every armed step (``outer_kernels.outer_aero_step``: tilt
  factor, angle of attack, nominal lift / drag, their z force; ``aero_estimate`` is its
  ``aero_lift_drag``);
- TAKEOFF / HOVER / LAND in one call (``mc_hold_step``: ``altitude.mc_altitude_law``, the
  z force, the position hold) and FIXED_WING's altitude and airspeed loops in one
  (``fw_longitudinal_step``: ``altitude.fw_altitude_law``, ``pusher_force``, the airspeed
  hold); the altitude-hold classes call the same laws (one home);
- the position hold's ``math.hypot`` is ``outer_kernels.hypot2``, a port of CPython 3.11's
  (``vector_norm`` for two values: power-of-two scaling, Dekker's exact squares, compensated
  sums, one differential correction; 3.11's divide-by-the-maximum branch when the maximum is
  subnormal, which 3.12 replaced): 0 differences from ``math.hypot`` on 10^6 pairs over the
  whole double range plus signed zeros, subnormals, the largest double, infinities, NaN
  (numba's ``math.hypot``, the C library's, differs in 349 of those pairs; a first port with
  3.12's subnormal branch differed in 19, all with a subnormal maximum).

Python function calls per control step (cProfile, ``--profile``): 73 -> 46. One semantic
note: a NaN produced inside ``fw_longitudinal_step`` from non-finite inputs can carry the
other sign bit than CPython's (the compiler may order the operands of a commutative + or *);
nothing reads it (the estimate rejects non-finite states, the allocator non-finite commands)
and no flight reaches it.

Measured A/B (main's tree and this branch's in alternate processes, each a warm-up then two
flights, the faster one's thread CPU per control step; 8 pairs at load 10-13.7): case 1
gs-shif 40 s main 31.8 us, branch 27.6 us (medians), pair ratio median 0.872 (0.74-1.45, 6
of 8 below 1); the campaign's first scenario (60 s, ``bench_campaign``'s spec) main 30.6,
branch 27.2 us, ratio median 0.911 (0.76-1.06, 6 of 8). 8 more pairs at load 2.4-6.3: case 1
main 38.5, branch 34.2 us, ratio median 0.895 (0.70-1.36, 6 of 8); campaign scenario main
37.1, branch 33.1 us, ratio median 0.887 (0.70-1.25, 6 of 8). An earlier set of 6 pairs with
the estimate and position hold only: medians 0.94 and ~1.0. ``bench_campaign.py --jobs 2
--scenarios 24 --no-dask`` on each tree back to back, twice: at load 10.6-11.6 main 51.4,
branch 40.0 scenarios/min, CPU of all the campaign's processes 0.57 and 0.56 s per scenario;
at load 5.2-8.6 main 40.7, branch 64.7 scenarios/min, CPU 0.67 and 0.52 s per scenario (the
flights took 1.8-2.9 s of wall time each: the cores were shared 3-6 ways, so the wall-time
rates say nothing about the code). No idle machine to measure on: on the lead's idle figures
(case 1 24.8-25.7 us per step; the campaign's flights 0.39-0.42 s) ratios of ~0.88-0.91 give
~21.6-23 us per step (~175-185x) and ~0.35-0.38 s per 60 s flight, i.e. ~315-340 scenarios/min
on 2 workers before the pool's ~3 %: around the 300/min line, an estimate from loaded ratios
whose spread is +-15-35 %, to be confirmed on an idle machine.

What is left per step (cProfile at load ~10, the campaign scenario): the vehicle kernel
(~10.6 us profiled), the QP kernel (~5.6), and the Python of ``run_scenario`` (~4.8),
``allocate_tracked`` (~4.1, with ``_count_solved``), ``Autopilot.step``, ``add_step``,
``OutputStage.allocate``, ``Vehicle.step``, ``HilRoundTrip`` (~3.5-3.9 each),
``OuterLoops.update`` and ``AttitudeStage.update`` (~3.2 each), ``Commander.update_mode``
with the mode machine and the navigator (~6 together); ``StateEstimate.update`` is ~4.8
profiled of which most is the call's five array arguments (the navigation state's four
arrays are views of one buffer in ``HilRoundTrip``, a ``NavState`` field for that buffer
would make it one). The next cuts: the front/back transitions and degraded lift (Python,
~13 % of the campaign's steps: 1,903 of 14,750), the mode machine's keyword calls, and
fusing the runner's per-step work (HIL round trip, metrics, vehicle) into one call.

Session 16, issue 24, branch inproc-16 (2026-12-03, 2 cores shared with two other helpers,
load 8-12 throughout). Profiled first on the campaign's first scenario (60 s, gs-shif,
``bench_campaign``'s spec; cProfile with ``time.thread_time``, py-spy at 2,000 samples/s): 45.4
Python calls per step; the largest Python lines were the runner's per-step wrappers
(``Vehicle.step``'s checks, ``HilRoundTrip.__call__``'s checks and ``NavState``,
``MetricsAccumulator.add_step``'s checks and conversions: ~8 % of the step together), the output
stage's bookkeeping (~7 %; ``v[2:] = tau`` alone 1-2 %), the outer loops' Python around their
kernels (~8 %) and the mode machine's keyword call with its four parameters every step.
Built (every flight bit-identical: ``command_digest.py`` dbd91a71..., 121a7434..., e937b801...
after each commit; and, since the digest flies with an observer, which keeps the separate
calls, observer-free flights hashed step by step (commands, navigation states, metrics, end
time) equal to main's for cases 1, 2, 0 and the campaign's first three scenarios):

- ``vtolftc/runners/inproc_kernel.py``: the runner's work after ``Autopilot.step`` (metrics
  sample, the vehicle's physics steps on the wire-rounded commands, the next step's HIL round
  trip) is one compiled call, ``runner_tail_step``, the same three kernels in the same order
  (no observer, state noise or HIL delay; else, and on the rare paths, the separate calls);
  its parts' one home: ``Vehicle.control_step_args``, ``MetricsAccumulator.kernel_arrays``,
  ``HilRoundTrip.kernel_home``, ``hil.nav_of_round_trip`` (``tests/test_runner_fused.py``:
  the kernel against the separate calls on random and adversarial inputs, whole flights
  with and without it, failing under 8 mutations);
- the front and back transitions' altitude law, z force, references and pusher ramp in one
  compiled call (``outer_kernels.mc_transition_step``), FIXED_WING's z force while the lift
  rotors ramp down in one (``mc_z_force_step``, also ``mc_hold_step``'s z force); the
  degraded-lift guidance stays Python (engaged in none of the campaign's 10 % losses);
- the mode machine's ``update`` only in the modes it can leave by itself
  (``modes.AUTO_EXIT_MODES``), ``ModeMachine.advance`` elsewhere (all ``update`` did there);
- the moment demand copied into the virtual command inside the allocation's compiled call
  (``allocate_tracked(..., v_tail=tau)``) instead of a numpy slice assignment (~0.35 us).

Python calls per control step (cProfile, the campaign scenario): 45.4 -> 43.0 (the fused
call replaces five calls, adds three small ones; the kernels' call overhead and the wrappers'
checks are what went). Thread CPU per control step, campaign scenario, main's tree and this
branch's alternated in processes (each a warm-up flight then the fastest of 2 or 5 flights):
8 pairs at load 8.8-10.7 (before the ``v_tail`` commit) main 29.4, branch 27.4 us (medians),
pair ratio median 0.93 (0.89-1.08, 7 of 8 below 1); 8 pairs at load 11.5-12.2 (final) ratio
median 1.03 (0.92-1.46); 8 pairs at load 8.3-11.5 (final, fastest of 5) ratio median 0.96
(0.91-1.12, 6 of 8 below 1). At this load the spread of one pair is +-10-15 %, larger than
the change; the load-free figure: callgrind (``--instr-atstart=no``, instrumentation switched
on with ``callgrind_control`` for one warm 60 s flight of that scenario, both trees run side
by side): main 3,248.7 M instructions, branch 3,057.0 M, ratio 0.941 (216.6 k -> 203.8 k per
step; the interpreter's own share grew 471 -> 491 M, the compiled calls' dispatch, type
checks and wrappers shrank more). The cut is ~6 % of a step (~1.5 us), not the 10-15 % asked;
on the lead's idle figures (main's campaign flight 0.38-0.40 s) ~0.36-0.38 s per flight,
~315-330 scenarios/min on 2 workers before the pool's ~3 % (an estimate, not measured idle).

Tried and dropped: ``v[2:] = tau`` written otherwise in Python (a kept view, ``np.copyto``,
three item stores of ``tolist()``: 321-421 ns against 377 ns, no gain); ``in`` on a tuple of
the four auto-exit modes (163 ns) instead of a frozenset (52 ns). Not done: the outer loops'
aerodynamics (``outer_aero_step``) inside the mode kernels (one dispatch and a ``tolist``
fewer per step, ~0.3-0.5 us), the degraded-lift guidance compiled, the allocation's
statistics (``_count_solved``) in its kernel, ``NavState``'s four views built once per step
(``nav_of_round_trip`` is now ~3.6 % of the step).

The lead's idle check after the merge (14:23-14:24 UTC, load 1.5-1.6, a new machine of this
kind, a Xeon with AVX512_SPR; session 15's base 1be7cc4 against main, interleaved, 2 pairs,
``--duration 120``): base 119.9 / 125.6x (33.4 / 31.9 us per step), main 127.3 / 127.5x
(31.4 / 31.4 us). This host runs a step ~25 % slower than the one that gave 155-161x in
session 14, so >= 150x is not met here.
Session 17, issue 24, branch inproc-17 (2026-12-03, 2 cores shared with three other helpers
and a CI run, load 7.5-15 throughout; every flight bit-identical: ``command_digest.py``
dbd91a71..., 121a7434..., e937b801... after each commit, and observer-free flights (cases 1,
2, 0 with gs-shif / shif / lqr and case 1 with shif, 40 s, commands and navigation state
hashed step by step, metrics, events, end time; the campaign's first three scenarios' result
rows) equal to main's). Built:

- the attitude stage's scheduled P-PID step inside the allocation's compiled call
  (``active_set._ppid_allocate_step_tracked``: ``scheduled_ppid3_step_packed``, then
  ``_allocate_step_tracked_packed`` with the P-PID's output as the moment tail, the same two
  kernels in the same order); ``AttitudeStage.kernel_step_args`` does the stage's work before
  the controller (ground reset, scheduled airspeed: its one home, ``update`` uses it) and
  hands the output stage the step's arguments, ``allocate_tracked(..., ppid=...)``; ``lqr``
  and a replaced ``update`` or ``allocate`` keep the separate calls
  (``tests/test_ppid_alloc_fused.py``: the fused call against the two calls on random and
  adversarial inputs, whole flights against the separate calls, the replaced allocator, the
  ground reset; failing under 6 mutations: the P-PID after the allocation, its saturation
  mask dropped, the scheduled airspeed scaled by 1 + 1e-7, the replaced allocator's P-PID
  step skipped, the ground reset removed or its height moved 0.5 -> 0.6 m);
- the runner's fused call decodes the next navigation state into two buffers used in turn,
  their ``NavState`` views made once, instead of ``np.empty(14)`` and four views per step
  (``nav_of_round_trip`` ~3.6 % of the step in session 16); the buffer written is never the
  nav the autopilot still holds (its estimate's ``last_nav``), tested step by step
  (``tests/test_runner_fused.py``; fails with one buffer or the other buffer's views).

Python calls per control step (cProfile): campaign scenario 43.0 -> 40.0, case 1 44 -> 41.
Callgrind (``--instr-atstart=no``, instrumentation on for one warm 60 s flight of
``bench_campaign``'s first scenario, main c84b3ba against this branch): 3,060.5 M -> 2,960.4 M
instructions (x0.967; 204.0 k -> 197.4 k per control step; the interpreter 491 -> 481 M, the
numba dispatch's type checks and unboxing ~5 M fewer). Thread CPU per control step,
main's tree and this branch's alternated in processes (a warm-up flight, then the faster of
two): the campaign scenario, 7 pairs at load 11.3-15.1: main 28.5-31.3 us (median 30.3),
branch 27.7-29.8 us (median 29.2), pair ratio median 0.983 (0.887-0.998, 7 of 7 below 1);
case 1 gs-shif 40 s, 7 pairs at load 7.5-10.6: main 28.4-32.0 (median 30.4), branch
28.5-30.4 (median 29.5), ratio median 0.969 (0.929-1.007, 5 of 7 below 1). The cut is ~3 %
of a step, not the ~15 % 150x needs on this host (31.4 us idle per step -> ~30.4 us by the
instruction ratio, ~131x).

Why not more: what a step spends is still spread thin. Per step, one warm campaign flight
under callgrind (of 197.4 k instructions): the two largest blocks of compiled code 28.9 k
and 12.9 k (not mapped to kernels; by their size the RK4 physics and the QP), libm's sin /
cos / atan2 / exp 5.9 k, the interpreter's loop 32.1 k (40 Python calls), numba's dispatch
(type codes, overload selection, unboxing, ``NRT`` adaptation, memory infos: ~10.5 k), malloc
/ free 8.6 k, ``numba_attempt_nocopy_reshape`` 2.5 k (the packed kernels' views: five
reshapes in the P-PID step alone). No single piece
left is worth more than ~2-3 %: ~15 % takes the one compiled call for the steady modes'
whole autopilot step (estimate, outer loops of the mode, P-PID, allocation on one flat state;
the mode machine's exits and the navigator's per-step work as compiled predicates, Python on
any event), which needs the navigator's fixed-wing lateral guidance (``fw_lateral``: loiter,
mission legs) compiled first: 54 % of the campaign's steps are fixed-wing. Not started here.
Tried and not kept: nothing else was built; the aerodynamics inside the mode kernels
(``outer_aero_step``: one dispatch and a ``tolist`` per step, ~0.3-0.5 us by session 16's
estimate, ~1 %) and the allocator's statistics in its kernel (``_count_solved``, one call,
~1 %) remain open.

The lead, main with inproc-17 merged against the session's base (c84b3ba, a clean clone's venv),
``--duration 120`` case 1, interleaved base / main, load 0.0-0.3 (17:12 UTC): 38.4 / 39.9,
43.4 / 38.3, 39.6 / 36.6 us per step (92-109x): the host ran ~20 % slower than at 17:08
(121.8 / 120.8x, 32.8-33.1 us, main) and than session 16 (127x); single runs move more than
the branch's 3 %. 150x (26.7 us) is not met on this host.

Session 18, issue 24, branch phys-18 (2026-12-03, 2 cores shared with two other helpers).
The physics side of the step (the runner's fused ``runner_tail_step``: metrics sample, 4 RK4
steps, HIL round trip). ``perf`` attached to 8 warm 60 s case-1 flights (no start-up) put
27.9 % of all samples on main on two instructions: the atomic increment / decrement of
numba's reference counts (``NRT_incref`` / ``NRT_decref``), done for every array argument at
every compiled call, 36 per call of the vehicle's 22-array ``derivatives`` (16 calls a step)
and ~100 more down the fused tail. Built, every flight bit-identical (``command_digest.py``
dbd91a71..., 121a7434..., e937b801... after each commit; ``/tmp/sub/longhash.py 150``: cases
1, 2, 0 and case 1 lqr, commands, truth, nav, metrics, events equal to main's):
``vtolftc.base.nrt.borrowed`` (views without ``meminfo``), taken by ``runner_tail_step`` and
``take_and_step_packed`` of their arguments and by ``step_n_memo`` for ``derivatives``;
``derivatives`` compiled with ``_nrt=False``; a rotor at exactly zero skipped; one ``sincos``
and one table search per evaluation (``bench_vehicle.py``'s docstring has the kernel's
figures; tests in ``tests/test_vehicle_borrowed.py``). After it: 12.0 % of the samples on
those two instructions, from the autopilot's kernels (not touched here: the same treatment
there is worth up to ~12 % of a step).

Measured. Callgrind (``--instr-atstart=no``, one warm 60 s case-1 flight instrumented by
``callgrind_control``): main 3,019.8 M -> 2,898.8 M instructions (x0.960, 201.3 k -> 193.3 k
per control step; ``NRT_incref`` / ``NRT_decref`` 84.7 M -> 40.0 M, the physics block
433.0 -> 385.8 M, ``__sincos_fma`` 27.9 M -> below 0.8 %): the instruction count understates
the gain, an atomic read-modify-write being one instruction of ~20 cycles. Thread CPU per
control step, case 1 60 s, main's tree and this branch's alternated in processes (warm-up,
then the faster of two flights): 8 pairs at load 2.35-2.74: main 24.2-27.8 us (median 25.2),
branch 20.2-22.6 (median 21.2), pair ratio 0.79-0.86 (median 0.85); 8 pairs at load 4.4-4.8
(40 s, before the last two commits): ratio 0.84-0.94 (median 0.88). This script, ``--duration
120``, 3 interleaved pairs at load 2.3-2.4: main 160.8 / 154.5 / 154.1x (24.9-26.0 us per
step, physics 10.9-11.4 us), branch 198.3 / 200.9 / 205.0x (19.5-20.2 us, physics 6.3-6.5
us): >= 150x with a ~30 % margin on this host today.
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import time

from vtolftc.runners.scenario import paper_scenario, run_scenario


def main() -> None:
    """Fly, print the per-stage breakdown (and the profile with ``--profile``)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", default="1")
    ap.add_argument("--controller", default="gs-shif")
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--top", type=int, default=25)
    args = ap.parse_args()
    if not args.duration > 0:
        ap.error(f"--duration {args.duration}: expected a positive number of seconds")
    run_scenario(paper_scenario(args.case, 2.0), args.controller)  # load the kernels
    scenario = paper_scenario(args.case, args.duration)
    steps = round(args.duration * 250)
    t0 = time.perf_counter()
    res = run_scenario(scenario, args.controller)
    wall = time.perf_counter() - t0
    print(f"case {args.case} {args.controller}: {args.duration:g} s simulated in {wall:.2f} s "
          f"({args.duration / wall:.1f}x real time, {1e6 * wall / steps:.1f} us per control "
          f"step); load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    total = res.timing_s["total"]
    for k in ("physics", "encode_decode", "autopilot", "observers"):
        v = res.timing_s[k]
        print(f"  {k:14s} {1e6 * v / steps:7.1f} us/step  {100 * v / total:5.1f} %")
    rest = total - sum(res.timing_s[k] for k in ("physics", "encode_decode", "autopilot",
                                                 "observers"))
    print(f"  {'runner loop':14s} {1e6 * rest / steps:7.1f} us/step  {100 * rest / total:5.1f} %")
    if args.profile:
        pr = cProfile.Profile()
        pr.enable()
        run_scenario(scenario, args.controller)
        pr.disable()
        st = pstats.Stats(pr)
        calls = sum(v[1] for v in st.stats.values())  # type: ignore[attr-defined]
        print(f"\n{calls / steps:.0f} Python function calls per control step (cProfile)")
        st.sort_stats("tottime").print_stats(args.top)


if __name__ == "__main__":
    main()

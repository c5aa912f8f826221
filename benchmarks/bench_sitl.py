"""SITL benchmark: real-time factor of the 40 s case in lockstep, and the HIL step round trip.

    python benchmarks/bench_sitl.py [--transport udp|zenoh|both] [--duration 40] [--case 1]
    python benchmarks/bench_sitl.py --parts   # the HIL codec pieces only, CPU per call
    python benchmarks/bench_sitl.py --floor   # the links' floor: 100-byte ping-pong, 2 processes
    python benchmarks/bench_sitl.py --transport udp --matrix [--trace] [--rt-priority N]
        # spin {0, 300} us x pinned {off, on}: one line each (--pin: autopilot CPU 0, vehicle 1)
    python benchmarks/bench_sitl.py --transport zenoh --duration 20 --spin-us 300 --pin
        --rt-priority 10 --zenoh-lowlatency --zenoh-peer-cpu   # (one command line)
        # zenoh's fast lockstep setting (session 17); the last line is the "summary [...]"

For each transport it flies the case with ``vtolftc.runners.sitl.run_sitl`` (vehicle and autopilot
as separate processes, ground-station commands, no plots) and reports:

- the real-time factor: simulated seconds / wall seconds from the start hold to the end hold
  (process start-up excluded);
- the round trip of one HIL step, measured in the vehicle process: from sending the step's
  HIL_SENSOR + HIL_STATE_QUATERNION datagram to receiving its HIL_ACTUATOR_CONTROLS (median,
  p90, p99), and the part of it spent in the autopilot's control step (step, status and the
  answer), the rest being the two link hops, parsing and the wake-ups;
- the CPU time per step of each process (all its threads), far less sensitive than the wall
  times to what else the machine runs (a heavily loaded machine still inflates it), and the
  load average;
- the CPU time of the autopilot's control step in the process (``step_cpu_mean_us``: step,
  status, answer) beside the CPU time of ``Autopilot.step`` in-process (a second in-process
  flight, thread CPU clock around each call);
- the per-part breakdown of a step: in the autopilot process ``Autopilot.step``, status +
  HIL_ACTUATOR_CONTROLS, and the work after the answer (metrics, run-folder writer, ground-
  station streams; overlaps with the vehicle); in the vehicle process the truth snapshot +
  physics, sensors + encoding of the next datagram, and its send;

and, for reference, the in-process run of the same scenario (same autopilot, no links).
Target of the issue: >= 20x real time over UDP, >= 15x over zenoh.

Measured (issue 24, session 10; 2 cores, load average 17-29 from seven other engineers' jobs,
so every wall figure below is the load's more than the code's):

- Why ``Autopilot.step`` costs 3-5x more in the process than in-process (same code, same
  inputs): the thread CPU clock says 139-220 us per step in the SITL process against 32-48 us
  in-process, so it is CPU, not preemption. Not numba dispatch (no specialisation compiled
  after ready; the decoder now hands the kernels views of one float64 array, the in-process
  layout, tested), not the garbage collector (2-3 collections, 0.2-0.3 ms in a 20 s flight;
  ``gc.disable`` changed nothing: 220 against 187 us), not the GIL (the figure is the control
  thread's own CPU; the other threads take about 135 us per step). It is the caches: in-process,
  a 300 us sleep before each step (what the process does while the vehicle computes) raises
  the step from 39-47 us to 94-126 us of CPU, an 8 MB memory sweep to 156 us. While the process
  waits, the core runs the vehicle (loopback UDP wakes it with a sync wake-up, on the waker's
  core) and other processes, and the autopilot comes back to cold L1/L2, TLB and predictors.
  Pinning the two processes to separate cores (``sched_setaffinity``) was worse under load
  (0.5-0.6x against 0.8-0.9x: no core to migrate to), busy-polling (``--spin-us 3000``) too
  (0.5x against 1.4x); SCHED_BATCH (no wake-up preemption) 0.84-0.96x against 0.75-0.86x,
  within the noise.
- Under this load UDP fell to 0.5-1.1x while zenoh kept 1.3-4.3x: a loopback UDP ``sendto``
  runs the receiver's wake-up in the sender (812-1026 us of wall time in status + answer,
  517-596 us in the vehicle's send, against 196-237 us and 96-108 us over zenoh, whose
  publisher hands the bytes to its own thread), so each process is preempted by the other
  in the middle of its step and the work after the answer lands on the critical path.
- Changes: HIL_STATE_QUATERNION decoded straight from the message
  (``protocols.hil.HilStateDecoder``: 9.7-10.0 us against 17.1-20.5 us per step, warm, same
  bits) and encoded in one compiled call in the vehicle (``HilStateEncoder``: 10-13 us against
  29-43 us, same bits). Pairwise with the main tree (interleaved, 3 runs each, 40 s), the
  per-step CPU of the two processes did not move beyond the load's noise (vehicle 643-820 us
  against 585-676 us; autopilot 994-1266 against 851-1014 us): a saving of 20-40 us a step is
  below what a load of 20 does to these figures, and the real-time factors (UDP 0.5-0.8x
  against 0.7-1.1x, zenoh 1.3-4.3x against 2.3-4.2x) only follow the load; a second pair
  at load 10-17 gave UDP 1.0x and 2.9x against 1.9x and 1.3x, zenoh 1.4x and 3.3x against
  1.5x and 0.9x (ratios 0.5-3.7 from one pair to the next).
- The 20x target means 200 us of wall time per step for both processes and both hops. The
  last measurements on a quieter machine (UDP 7.8-8.5x, zenoh 4.4-4.9x) spent about 500 us a
  step; on this machine the cold autopilot step alone is 94-220 us of CPU, the vehicle's
  physics + sensors + encoding 130-250 us, and a loopback round trip about 170 us: the
  processes' Python per step, run on caches the other process emptied, is what stands between
  them and 20x, not the link.

Session 12 (issue 24; 2 cores shared with 3-4 other engineers' jobs, load average 5-11 through
every measurement below, so the wall figures are again the load's):

- Profile of both process mains per step (cProfile, warm numba cache, 10 s UDP flight): in
  the autopilot's control thread the socket ``send`` of the answer (the receiver's wake-up
  runs in the sender), ``Autopilot.step``, the link's read and parse, the generated
  HIL_ACTUATOR_CONTROLS encoding (message, header and signature objects, CRC and SHA-256 in
  Python calls), then the observers (ULog, rerun, run folder: already decimated to their
  rates), metrics, failsafe and ground-station hand-over; no per-step class building, no
  numba dispatch. The other threads of the autopilot process (``/proc`` per-thread CPU): the
  ground-station worker about 48 us per step, rerun's threads about 16 us, the rest ~0. In the
  vehicle: the state datagram (sensors, two generated encodings, signing), the send, the
  truth snapshot and physics; after the send the truth-log formatting and the battery.
- Changes: HIL_ACTUATOR_CONTROLS, HIL_SENSOR and HIL_STATE_QUATERNION packed by one
  ``protocols.fastpack.FramePacker`` each (``struct.pack_into`` a buffer made once + one numba
  call for header, zero-tail truncation and CRC, SHA-256 signing from a copied key hash; the
  generated encoding's bytes, tested over 181 message classes, signed and unsigned); the
  autopilot answers straight after ``Autopilot.step`` (armed from ``metrics_inputs``, the
  status snapshot after the send) and no longer reads the link once more after each step;
  the noise-free sensors stop making zero arrays and a projection per call (same bits).
- ``--parts`` (warm, thread CPU, interleaved in one run, load 8): answer 6.2 -> 2.7 us (min;
  median 9.0 -> 4.1), HIL_SENSOR 7.5 -> 2.2 us; the vehicle's whole state datagram
  (sensors + the two encodings) 25.4-26.6 -> 17.3-17.4 us (min of 5, main's tree against this
  one, 2 interleaved pairs at load 11).
- In flight, pairwise against main (interleaved, 20 s of case 1, 3 pairs per transport, load
  8-11). zenoh: CPU per step autopilot process 719 / 832 / 727 -> 527 / 587 / 468 us, vehicle
  517 / 606 / 519 -> 412 / 448 / 389 us, sensors + encode 120 / 153 / 95 -> 79 / 80 / 66 us,
  real-time factor 3.1 / 2.1 / 3.8 -> 3.3 / 2.3 / 4.1x (a second set of 3 pairs with the
  last commit, load 9: autopilot 638 / 567 / 642 -> 496 / 809 / 398 us, vehicle 414 / 442 /
  494 -> 380 / 515 / 286 us, 3.2 / 4.9 / 3.7 -> 6.1 / 2.7 / 5.1x: one pair the other way).
  UDP: sensors + encode 85 / 127 / 87 -> 62 / 65 / 79 us; CPU per step autopilot 404 /
  661 / 433 -> 395 / 369 / 479 us, vehicle 306 / 466 / 284 -> 285 / 258 / 303 us;
  real-time factor 5.9 / 1.8 / 4.1 -> 4.0 / 4.1 / 2.9x: at this load one UDP pair's ratio swings
  both ways by 2x, the CPU figures' by 1.5x.
- Not reached: 20x / 15x. Where the time goes (UDP, the lead's idle-machine figures and the
  profile): a step is two hops, each a loopback ``sendto`` whose wall time carries the
  receiver's wake-up (35-365 us measured here, depending on who else runs), plus the two
  processes' Python between the waits: autopilot ~60-80 us of ``Autopilot.step`` (another
  engineer's code), ~120-150 us after the answer (metrics, observers, failsafe, ground-station
  hand-over: on the critical path whenever the vehicle's ~100 us step is shorter), the read
  and parse ~30 us; vehicle ~30 us physics, ~60-80 us sensors + datagram, ~60 us after the
  send (truth-log formatting ~30 us, battery ~20 us). With ~400 + ~300 us of CPU per step in
  the two processes on two shared cores, 200 us of wall per step is out of reach of these
  per-step savings (tens of us each); it needs the autopilot step and the after-answer work
  compiled, or both ends in one process.

Session 13 (issue 24; 2 cores shared with 4 other helpers, load average 7-13 through every
measurement below; the lead's idle figures of the issue: UDP 14.3x, zenoh 6.9x):

- Profile per part, wall / thread CPU (``part_mean_us`` / ``part_cpu_mean_us`` in both
  summaries, :class:`vtolftc.telemetry.step_parts.StepParts`; new parts ``wait_and_read`` and
  the vehicle's ``after_send``). UDP, 10-20 s of case 1, 6 flights at load 11-13, us per step:
  autopilot wait_and_read 514-2034 / 73-117 (the wait for the vehicle, then read, parse and
  decode), ``Autopilot.step`` 50-74 / 49-70, status + answer 120-179 / 26-38 (the wall is the
  vehicle's wake-up run in the sender), after the answer 139-182 / 75-100; vehicle
  wait_and_read 734-2140 / 50-84, truth snapshot + physics 25-38 / 23-33, sensors + encode
  60-93 / 49-69, send 83-287 / 15-21, after the send 53-75 / 48-67. The CPU on the critical
  path is therefore ~75-115 (read) + ~55 (step) + ~30 (answer) in the autopilot and ~50-80
  (read) + ~25 (physics) + ~55 (sensors, encode) + ~17 (send) in the vehicle: 300-380 us of
  CPU per step, before any waiting. 20x is 200 us of wall time per step.
- Warm, one process, loopback (the same pieces called back to back, thread CPU, min / median
  of 5 x 2000, load 11-12): vehicle datagram 27-31 us, autopilot read + parse 24-25 us and
  decode 6 us, answer 10-11 us, vehicle read + parse 14-15 us. The flights' figures are 2-4x
  these: each process runs on caches the other one (and the other jobs) emptied while it
  waited; that, not the link, is most of the gap.
- The links' floor (``--floor``; 100-byte ping-pong between two processes, loopback, 3 runs at
  load 12-12.7, median round trip / CPU per round trip of one end): UDP sockets 15-17 / 9-23 us;
  raw zenoh (peer mode, scouting off) with a Python callback + queue 104-154 / 51-88 us, with
  zenoh's FIFO channel 94-112 / 61-65 us; our ``ZenohTransport`` with the callback 94-146 /
  52-96 us, with the channel 90-93 / 52-64 us. So zenoh's own floor is ~80-90 us per round trip
  above UDP's, and our transport adds nothing measurable on top of it; the zenoh flights'
  extra (median round trip 366-539 against UDP's 309-613 us here, 424 against 190 us idle) is
  that floor plus zenoh's threads competing for the two cores.
- Change: the HIL link over zenoh receives through zenoh's FIFO channel (``receive="channel"``,
  :mod:`vtolftc.protocols.zenoh_transport`): no Python callback and no GIL in zenoh's thread,
  the sample read in the waiting thread; timed waits are ended by a watchdog thread (an empty
  payload to the session itself). Ground-station links keep the callback (bounded queue that
  drops and counts: a GCS that stops reading must not block the autopilot's publisher).
  In flight, pairwise against main (6 interleaved pairs, 10 and 20 s, load 11-13.7): CPU per
  step of the autopilot process 397 / 397 / 449 / 461 / 449 / 343 -> 445 / 406 / 415 / 379 /
  435 / 384 us (mean 416 -> 411), vehicle 255 / 289 / 338 / 372 / 330 / 248 -> 338 / 302 /
  337 / 276 / 309 / 290 us (305 -> 309), real-time factor 3.5 / 3.6 / 3.1 / 2.6 / 2.1 / 4.9 ->
  4.7 / 4.2 / 2.6 / 2.7 / 3.1 / 3.5x: no difference the load lets one see; kept for the floor's
  lower and steadier round trip.
- Change: ``FastParser`` builds messages without arrays or chars through one precomputed
  ``itemgetter`` and those with arrays through one comprehension (same objects, tested over the
  dialect): autopilot read + parse 26.7 -> 24.8 us warm (min), 2-4 us per step.
- UDP in flight, pairwise against main (3 interleaved pairs, 20 s, load 12.9-13.7): CPU per
  step autopilot 357 / 507 / 384 -> 407 / 272 / 323 us, vehicle 248 / 339 / 271 -> 276 / 187 /
  231 us, real-time factor 2.7 / 1.8 / 2.5 -> 2.5 / 4.1 / 3.1x: within the load's noise, as
  expected of a 2-4 us saving.
- At the session's end the machine went quiet (load 0.9-1.3): 2 interleaved pairs, 20 s,
  ``--transport both``, main -> this tree, wall per step (real-time factor) and CPU per step
  autopilot / vehicle process: UDP 356 (11.2x), 431 (9.3x) -> 448 (8.9x), 357 us (11.2x);
  CPU 259 / 248, 331 / 240 -> 355 / 245, 277 / 196 us. zenoh 784 (5.1x), 759 (5.3x) -> 865
  (4.6x), 642 us (6.2x); CPU 527 / 396, 507 / 394 -> 599 / 449, 443 / 335 us. The same
  picture: no change beyond one pair's spread. In these idle flights the thread CPU of the
  critical path was autopilot read 79-98 + step 43-54 + answer 38-47 us and vehicle read
  59-72 + physics 22-26 + sensors and encode 44-58 + send 25-29 us (UDP): ~310-430 us of CPU
  per step, still 2-3x the warm costs.
- Bounded busy-poll (``--spin-us``, both processes; kept opt-in): UDP, 4 pairs at load 7-8
  (20 s) and 2 at load 11-12 under ``nice -10`` (10 s). The median round trip falls (338 ->
  162, 274 -> 170 us at load 7) but the mean and p99 rise (p99 5-7 ms); CPU per step mostly
  +30-160 us per process (one pair -40 us); real-time factor without / with 5.9 / 5.8 / 5.7 /
  6.1 / 1.6 / 4.2 against 6.1 (300 us) / 6.3 (100) / 5.3 (300) / 2.6 (100) / 1.7 (150) /
  2.6x (150). With more runnable
  jobs than cores a spinning process loses its sleeper credit and is preempted for whole
  slices, and the spin takes the core the peer needs; it can only pay with an idle core,
  which this machine did not have during the session, so it is not the default.
- Not reached: 20x / 15x. Where the time goes (above): ~300-380 us of CPU per step on the
  critical path at this load, of which reads and parses ~130-190 us, the two processes' Python
  step work ~165 us; every wait is a sleep and a wake-up on a cold cache. On the idle machine
  the lead measured 280 us per step (UDP) with 363 us of CPU per step in the two processes
  together: 200 us needs both the critical-path CPU down by about a third (a compiled HIL
  codec end to end: parse + decode and sensors + encode in one call each, ~100 us of today's
  in-flight CPU) and the caches kept warm (a spin on an idle core), neither of which this
  loaded machine can show.

Session 14 (issue 24; 2 cores shared with 2 other helpers, load average 5-9 through the
flights below, 0.1-6 through the warm figures):

- Warm pieces (one process, thread CPU): the vehicle's state datagram 15-17 us, of which
  ``Vehicle.sensors`` 8.8-9.4 us (``dcm`` 2.2, the sample's small numpy arrays and its frozen
  dataclass ~5), HIL_SENSOR and HIL_STATE_QUATERNION packing 2.0 + 1.9 us (a numba call and
  SHA-256 from a copied key hash: 0.4 + 0.15 us), the state encoding 1.4 us; the autopilot's
  read of a step datagram (``--parts`` ``read_fast``, in-memory transport) 13.1 us against 23.9
  us through the generated parser alone; over a real loopback socket 20.5-23.5 us. Of the read,
  ``FastParser._build`` (the message objects the link hands over, identical to the generated
  parser's: header, buffers, signing flags) is ~5 us, SHA-256 of two frames ~1 us,
  ``HilBridge.handle`` + ``HilStateDecoder`` ~3 us, each syscall ~1 us (a failed non-blocking
  ``recvfrom`` with its exception 1.15 us, a ``select`` on a ready socket 1.27 us: trying
  ``poll`` first instead measured 26-28 against 22-25 us, dropped).
- Change: the framing checks and the CRC of every frame of a datagram in one compiled call
  (``fastparse._scan_kernel``; CRC_EXTRA from a table made once from the dialect). Interleaved
  in one process against main's ``FastParser`` (6 x 3000 signed step datagrams, load 5.6):
  10.1-10.8 -> 9.2-12.5 us per datagram, i.e. ~0.5-1 us: the per-frame Python it replaced was
  already one ``struct`` unpack and one C CRC call; the objects built after it dominate. With
  the signature hash from a copied SHA-256 state of the key (as ``FramePacker``): min 10.35 ->
  10.19 us, median 14.3 -> 12.8 us (14 interleaved x 2000, load 9.7).
- Change: ``HilBridge.drain`` reads once per step when the link says it read everything
  (``Link.drained``: the transport's batch was not full, nothing came from the pending queue),
  instead of a second read that fails: real UDP socket, warm, 20.5-23.5 -> 17.3-19.7 us per step
  (with both changes).
- In flight, pairwise against main (3 interleaved pairs, 20 s of case 1, ``--transport both``,
  load 5.0-6.7), main -> this tree. UDP real-time factor 4.6 / 3.3 / 4.9 -> 2.3 / 7.5 / 6.6x,
  CPU per step autopilot process 294 / 386 / 365 -> 507 / 282 / 351 us, vehicle 220 / 244 / 210
  -> 337 / 197 / 241 us, autopilot wait_and_read CPU 90 / 105 / 104 -> 142 / 81 / 95 us. zenoh
  4.4 / 5.9 / 7.6 -> 4.6 / 6.4 / 6.6x, CPU autopilot 452 / 396 / 344 -> 451 / 417 / 421 us,
  vehicle 331 / 319 / 255 -> 344 / 322 / 318 us. The first new UDP flight ran while another
  helper's burst took the cores (every part of it 1.5x); otherwise the pairs move by less than
  one pair's spread: a few us per step is below what this load does. A second set with the
  last commit (3 pairs, load 13.4-17.1): UDP 2.8 / 3.6 / 8.9 -> 2.0 / 5.0 / 8.7x, CPU per step
  autopilot 424 / 295 / 265 -> 332 / 263 / 279 us, vehicle 314 / 225 / 191 -> 242 / 189 / 206
  us, autopilot read 123 / 90 / 74 -> 97 / 75 / 81 us; zenoh 2.6 / 2.4 / 5.2 -> 2.2 / 6.0 /
  6.6x, CPU autopilot 438 / 381 / 498 -> 436 / 399 / 382 us, vehicle 322 / 294 / 356 -> 314 /
  288 / 281 us, autopilot read 82 / 70 / 89 -> 78 / 75 / 63 us. Mean autopilot read CPU over
  the 6 UDP pairs 97.7 -> 95.2 us (85.8 without the loaded flight): the direction of the warm
  saving, not separable from the noise.
- Not reached: 20x / 15x (this tree's best flights here 7.5x UDP, 6.6x zenoh; main's 4.9x, 7.6x;
  load 5-7). Where the remaining time goes (the flights above but the loaded one, thread CPU per
  step): autopilot read 69-105 us, ``Autopilot.step`` 37-56 us, status + answer 33-50 us, after
  the answer 67-97 us; vehicle read 43-80 us, physics 19-29 us, sensors + encode 42-63 us, send
  17-31 us, after the send 42-64 us. The critical path's CPU in flight is 3-5x the warm figures
  (read 13-20 us warm against 70-100 in flight; sensors + encode 15-17 against 42-63): cold
  caches after every wait, as sessions 10 and 13 found. A compiled codec saves at most the warm
  Python (~10 us of the read, ~12 us of sensors + encode); the message objects the link must
  hand over (ULog, ground-station streams and the bridge read HIL_SENSOR / HIL_STATE_QUATERNION
  messages) and ``Vehicle.sensors`` (the vehicle model, another owner's) stay in Python unless
  the HIL step bypasses the message objects altogether (decode the two frames straight into the
  NavState array and the sensor fields, making the message objects only when an observer asks):
  the next step, not started here for lack of time.

Session 15 (issue 24; 2 cores shared with 2 other helpers, load average 9-16 through every
measurement below):

- Change: the HIL step without message objects. ``Link.defer(ids)`` makes the fast parser
  hand the step's frames over as ``fastparse.RawFrame`` (framing, CRC, signature, replay
  window and counters as before; the message object made by ``RawFrame.message()`` only when
  asked). The autopilot decodes HIL_STATE_QUATERNION into its ``NavState`` in one compiled
  call (``hil_frames.HilStateFrameDecoder``, ``HilStateDecoder``'s bits) and reads
  HIL_SENSOR's time from the bytes; ``HilBridge.last_sensor`` / ``last_state`` make the
  message objects for ULog and the ground-station streams when they look (decimated). The
  vehicle reads HIL_ACTUATOR_CONTROLS in one compiled call (``hil_frames.actuator_controls``)
  and packs HIL_SENSOR (from the sample's arrays) and HIL_STATE_QUATERNION (the state's
  encoding fused in) in one compiled call each (``hil_frames.HilFramePackers`` through
  ``FramePacker.pack_compiled``: the same bytes, signing and sequence numbers). Anything the
  compiled paths decline (a corrupt datagram, a NaN quaternion, a float32 overflow) takes
  today's path. ``tests/test_hil_frames.py`` compares both paths value by value and byte by
  byte (random fields, truncated payloads, corrupted flights, signed and unsigned).
- Warm (one process, thread CPU, interleaved): autopilot read of a step datagram
  (``--parts`` ``read_fast``, 3 + 2 pairs against main's tree at load 9.6-12.3) min 14.8 /
  16.5 / 15.3 / 18.7 / 15.3 -> 15.8 / 9.8 / 10.1 / 15.6 / 11.3 us, i.e. ~5 us (a third) off
  when the two runs are alike; the vehicle's signed state datagram, general against compiled
  packers in one process (12 x 2000 each, load 10.4-10.7) min 17.9 / 18.7 -> 16.4 / 16.9 us,
  median 19.6 / 22.4 -> 16.7 / 20.4 us (``Vehicle.sensors``, another owner's, is ~10 us of
  it); the vehicle's read of a signed HIL_ACTUATOR_CONTROLS + the commands, message against
  frame (12 x 2000, load 10.0), min 7.6 -> 7.1 us, median 11.0 -> 8.9 us.
- In flight, pairwise against main (interleaved main, this, main, ... : 5 main and 4 new
  flights of 20 s of case 1, ``--transport both``, load 9.1-15.8), main -> this tree:
  UDP real-time factor 2.3 / 4.1 / 3.8 / 2.5 / 5.2 -> 3.9 / 1.7 / 4.0 / 3.3x, CPU per step
  autopilot process 521 / 426 / 430 / 621 / 300 -> 477 / 604 / 452 / 380 us (mean 460 ->
  478), vehicle 375 / 303 / 336 / 426 / 227 -> 338 / 418 / 336 / 276 us (333 -> 342),
  autopilot wait_and_read CPU 144 / 112 / 122 / 176 / 83 -> 120 / 140 / 104 / 83 us (127 ->
  112), vehicle sensors + encode CPU 99 / 80 / 71 / 109 / 59 -> 81 / 111 / 76 / 74 us;
  zenoh 2.5 / 3.7 / 6.6 / 3.6 / 2.7 -> 0.9 (load 15.8) / 3.3 / 4.2 / 5.2x, CPU autopilot
  677 / 522 / 405 / 597 / 582 -> 639 / 560 / 643 / 422 us, vehicle 530 / 403 / 360 / 453 /
  529 -> 478 / 420 / 475 / 343 us, autopilot read 125 / 93 / 61 / 111 / 110 -> 94 / 86 /
  82 / 59 us (mean 100 -> 80). The reads move the way of the warm saving; nothing else can
  be told from the load's noise (one pair's spread is 2x). Two more pairs at the end, load
  2.8-3.8 (this, main, this, main): UDP 7.9 / 7.6 against 7.7 / 8.1x (wall per step 506 /
  527 against 517 / 497 us), CPU per step autopilot 352 / 299 against 302 / 288 us, vehicle
  217 / 231 against 229 / 206 us, autopilot read 80 / 64 against 78 / 69 us; zenoh 6.3 /
  5.4 against 5.2 / 5.1x (636 / 742 against 770 / 780 us), CPU autopilot 425 / 454 against
  544 / 535 us, vehicle 352 / 347 against 429 / 411 us, autopilot read 59 / 69 against 95 /
  106 us. UDP unchanged within its spread; zenoh 5-20 % quicker in both pairs, more than the
  warm saving explains (2 pairs: not established).
- ``test_coldstart``'s fresh-cache SITL flight failed once (take-off not within 90 s, load
  11-16, the fast suite running beside it) before the frame kernels were compiled at start
  (``hil_frames.warm_up``, called by ``HilBridge`` and ``StateEncoder``); with it, it passed
  alone (153 s, load ~4-6).
- Not reached: 20x / 15x (best flights here 7.9x UDP, 6.3x zenoh at load 3-4; main's 8.1x,
  5.2x). Where the time goes, measured in these flights (thread CPU per step, UDP):
  autopilot read 83-140 us (its warm cost is now ~10 us: the rest is the wake-up on cold
  caches and the syscalls), ``Autopilot.step`` 62-93 us, status + answer 40-66 us, after the
  answer 118-167 us (metrics, observers, ground-station hand-over: on the critical path
  whenever the vehicle is quicker); vehicle read 73-127 us, physics 31-44 us, sensors +
  encode 74-111 us (warm 16-17 us, of which ``Vehicle.sensors`` 10 us), send 22-34 us. The
  codec's warm cost on the critical path is now ~10 us (autopilot read) + ~6 us (vehicle
  packing) + ~7 us (vehicle read): there is nothing left of the codec worth compiling; the
  in-flight figures are 3-8x the warm ones, as sessions 10, 13 and 14 found, because every
  step begins with a wake-up on caches the other process (and the other jobs) emptied. On
  an idle machine (the lead's 280 us / 14x UDP) this session's saving is at most ~10-15 us
  a step of warm CPU, ~5 %: 20x (200 us) needs the after-answer work off the critical path
  and both processes on warm cores (one process, or pinned cores with spinning on an idle
  machine), which this loaded machine cannot show.

- The lead's idle check after the merges (main dac415f against 1f51d91, clean-clone venvs,
  interleaved, 2 pairs of ``--transport both``, load 1.3-1.6, nothing else running): UDP
  9.6 / 11.1x -> 10.3 / 10.8x (round trip median 269 / 220 -> 241 / 234 us, mean 404 / 364
  -> 376 / 372 us), zenoh 6.6 / 6.2x -> 6.3 / 6.5x. No change beyond the noise: the mean
  round trip is 1.5-1.6x its median (p99 1.2-1.7 ms), so the slowest tenth of the steps
  costs as much as the codec work saved. Not the garbage collector: both processes with
  ``gc.set_threshold(200000, 100, 100)`` (a ``sitecustomize``, 2 pairs) gave 10.3 / 10.3x
  against 10.2 / 10.4x. ``--spin-us 300`` beside one busy helper (load 0.8): median round
  trip 234 -> 143 us but p90 424 -> 1009 us, 10.0 -> 8.9x: spinning pays only on cores
  nothing else wants.

Session 16 (issue 24; 2026-12-03; 2 cores shared with 2 other helpers, load average 6-12 through
every flight below, so the wall figures are indicative; UDP, 20 s of case 1):

- Tools: ``--trace`` (both processes record every step's parts, wall / thread CPU / end time on
  the shared monotonic clock, and the control thread's context switches and page faults,
  ``StepParts.enable_trace``); each round trip is cut into ``ap_busy`` (the autopilot still in
  the previous step's after-answer work when the state left), ``up`` (send, wake-up, read),
  ``ap_compute``, ``vehicle_busy`` (the vehicle still in its after-send work when the answer
  left) and ``down``. ``--pin`` (``--cpu N`` of both programs: the autopilot on CPU 0, the
  vehicle on CPU 1), ``--rt-priority N``, ``--matrix`` (``--spin-us`` {0, 300} x pinned {off,
  on}, one line each).
- The tail, before this session's change (load 6-7): 9.9 % of the steps took over 1 ms and
  held 46 % of the round-trip time (mean 650 us, 387 us without them). Mean minus median per
  part, wall: autopilot wait_and_read 87, status_and_answer 68 (the wake-up the send runs),
  after_answer 55 us; vehicle wait 188, send 104 us; in CPU only after_answer has a tail (35
  us). The autopilot's after-answer CPU was over 300 us in 42 steps, 40 of them at each 0.5 s
  of simulated time: the rerun recorder's send of its buffered rows (1.5-2.2 ms of CPU, 3-7 ms
  of wall, measured in-process and in the traces), which sat on the critical path (``ap_busy``
  over 500 us in 40-59 steps of a 20 s flight, each 5-7 ms: ~50 us of the mean step). Per
  step, in the SITL autopilot (thread CPU, mean / p99): metrics 9.6 / 22, run folder 23.5 /
  65, rerun 17.4 / 34 (max 2456), event log 0.7, ULog 19.6 / 144, failsafe 6.6, ground-station
  hand-over 9.3 / 48 us.
- Not the GIL: steps where the control thread slept more than once (a GIL wait is a second
  voluntary switch) were 0.1-3.8 % at the 1 ms switch interval; 0.1 ms gave 0.6-15 % and
  1.5 / 3.6 / 3.9x against 6.2 / 4.6 / 4.2x (3 interleaved pairs, load 7-9: noise, no gain).
  Not page faults (0.1-0.2 minor, no major, per step and thread). Not the disk on the vehicle
  (its after-send work over 500 us of wall in 11 of 5000 steps).
- Unpinned, ``vehicle_busy`` was 188-229 us a step and ``ap_busy`` 80-151 us: the loopback send
  wakes the peer on the sender's core, where it waits for the sender's after-send work.
  Pinned (2 pairs, load 6.2-7.0): ``vehicle_busy`` 0-3 us, the vehicle's involuntary switches
  0.46 -> 0.01 per step, 4.4 / 3.4x unpinned against 3.0 / 3.6x pinned: the loaded cores' other
  jobs then preempt a pinned process that cannot move (session 10's finding); what is left is
  ``up`` / ``down``, the wake-ups on cores other jobs hold (involuntary switches in 14-47 % of
  the autopilot's steps): not ours.
- Change: the SITL autopilot's recorder sends in pieces while the loop waits
  (``RerunRecorder(deferred=True)``, ``idle_work``; the wait for rerun's writes in its flusher
  thread). 3 interleaved pairs at load 11-12, before -> after: the 40 largest after-answer
  steps 3189 / 2573 / 3497 -> 432 / 660 / 436 us of CPU, ``ap_busy`` 173 / 125 / 125 -> 86 /
  205 / 56 us per step, 3.21 / 3.26 / 3.50 -> 3.56 / 1.87 / 4.28x (the load's noise is larger
  than the ~50 us a step it saves; on an idle machine, ~20-30 us of ~350).
- Left of ours: at each 0.5 s of simulated time ~380 us of after-answer CPU (the run folder's
  and the ULog's flushes), every 20 ms ~150 against ~65 us (the ULog's 50 Hz topics, rerun's
  rows): ~20 us a step on average, on the critical path only when the vehicle is quicker.
- Against main at the end of the session (3 interleaved pairs, load 3.2-4.7, main -> this
  tree): 7.2 / 4.8 / 3.6 -> 7.4 / 5.4 / 4.0x, round trip mean 618 / 869 / 1127 -> 573 / 712 /
  977 us, p99 4269 / 5006 / 8071 -> 3904 / 4623 / 5812 us, CPU per step of the autopilot
  process 332 / 353 / 357 -> 334 / 312 / 367 us: every pair the same way, each within the
  spread of one pair at this load.
- ``--matrix`` (load 5.2-6.6): spin 0 unpinned / pinned 4.7 / 3.5x (round trip mean / median
  922 / 331, 1150 / 291 us), spin 300 unpinned / pinned 6.3 / 4.3x (672 / 95, 906 / 100 us);
  with ``--trace`` while the fast test suite ran beside it (load 10): 2.1 / 1.7x, 1.7 / 2.2x.
  Pinned loses on a loaded machine, as in session 10; only the idle machine can say what
  pinning and spinning give.
- The lead on the idle machine after the merges (14:17-14:19 UTC, nothing else running, load
  1.0-1.8; 20 s of case 1, one flight per line, in this order), real-time factor, round trip
  mean / median / p90 / p99 us, CPU per step autopilot / vehicle process us:

  ========================================  =====  =========================  =========
  UDP                                       x      round trip (us)            CPU (us)
  ========================================  =====  =========================  =========
  ``--matrix``: spin 0, not pinned          12.1   418 / 205 / 328 / 1019     277 / 186
  spin 0, pinned                            12.3   421 / 211 / 344 / 1019     259 / 175
  spin 300, not pinned                      16.9   337 / 89 / 309 / 1268      239 / 179
  spin 300, pinned                          17.2   344 / 99 / 341 / 1195      230 / 191
  ``--spin-us 1000``                        17.2   336 / 94 / 331 / 1281      239 / 201
  ``--spin-us 1000 --pin``                  20.7   305 / 86 / 271 / 989       190 / 173
  ``--spin-us 300 --pin --rt-priority 10``  24.8   275 / 81 / 151 / 671       162 / 147
  ``--spin-us 3000 --pin``                  19.7   319 / 89 / 297 / 1009      201 / 187
  ``--spin-us 300 --pin --rt-priority 10``  25.3   275 / 77 / 148 / 619       157 / 144
  default (nothing)                         12.2   418 / 203 / 324 / 1009     270 / 185
  ========================================  =====  =========================  =========

  ``vtolftc sitl --spin-us 300 --cpus 0,1 --rt-priority 10`` (40 s of case 1 with its run
  folder): 24.2x, the metrics those of the docs (roll / pitch / yaw RMSE 0.2325 / 0.6756 /
  0.3053 deg). So UDP's 20x is reached on two free cores when each process has a core of its
  own, keeps it warm (spin) and is not preempted there (``SCHED_FIFO``): the CPU of a step falls
  by 40 % (cold caches and idle-state wake-ups were most of the in-flight cost, as sessions 10
  to 15 found) and the round trip's p90 halves.
  zenoh, same hour: default 6.5x (691 / 446 / 705 / 1907 us), ``--pin`` 8.0x, ``--spin-us 300``
  6.4x, ``--rt-priority 10`` 6.2x, spin 300 + rt 10 7.1x, spin 300 + pin + rt 10 3.3x, spin
  1000 + pin + rt 10 1.5x (2750 us round trip: zenoh's own threads pinned beside a spinning
  ``SCHED_FIFO`` thread get no CPU). zenoh's 15x is not reached: its round trip's floor is
  ~80-90 us above UDP's (session 13's ``--floor``) and its runtime threads need the cores the
  spin would keep.

Session 17 (issue 24, zenoh; 2026-12-03; 2 cores shared with 2-3 other helpers, load average
9-16 through every flight below; 20 s of case 1; "main" is the main tree at the same flags):

- How a zenoh HIL step travelled: the sender's ``put`` handed the frame to zenoh's TX thread
  (universal transport), which wrote the TCP socket; the receiver's RX thread (tokio worker
  ``rx-N``) read it and pushed it into the FIFO channel that the control thread polls
  (``--spin-us``) or sleeps on: three threads per hop (UDP: one). With ``--spin-us 300 --pin
  --rt-priority 10`` every thread of a process was ``SCHED_FIFO`` 10 on its one core, so the RX
  thread could not run until the spinning control thread gave up: each hop cost the whole
  spin. main's ``--trace``: 100 % of the steps over 1 ms, ``up`` 602 / ``down`` 623 us, 2.6x.
- Changes (each opt-in but the first, which only touches processes with zenoh threads):
  ``--rt-priority N`` puts zenoh's runtime threads (``rx/tx/app/acc/net-N``) at N + 1, so the
  reader preempts the spinner at once (:mod:`vtolftc.runners.processes.priority`); the HIL
  link on zenoh's low-latency transport (``--zenoh-lowlatency``, URL ``lowlatency=1``, QoS
  off: the publishing thread writes the socket, no TX thread); ``--zenoh-peer-cpu`` (programs'
  ``--zenoh-cpu M``) puts each process's zenoh threads on the *other* process's core, where
  the sample was sent from and whose control thread only waits for the answer then: the
  reader wakes locally inside the sender's write and the receiving control thread keeps its
  core and caches (:mod:`vtolftc.runners.processes.affinity`).
- Interleaved flights, ``--spin-us 300 --pin --rt-priority 10``, real-time factor / round trip
  median / CPU per step autopilot, vehicle process (us): main 2.7 / 1294 / 834, 730; 2.6 /
  1360 / 824, 732; 2.6 / 1360 / 852, 770; 2.5 / 1429 / 865, 778; 2.5 / 1429 / 855, 772.
  With the priority change only 10.3 / 258 / 381, 355 and 9.5 / 261 / 396, 350; + low-latency
  11.4 / 222 / 340, 321, 10.4, 11.9, 11.3, 11.0, 11.1x; + peer CPU (the fast setting) 17.1 /
  115 / 225, 212; 16.7 / 127 / 239, 223; 16.7; 17.2 / 119 / 226, 210; 15.0 / 125 / 256, 216;
  17.0 / 120 / 232, 214 (p90 225-243 us, p99 802-2065 us); spin 1000: 17.2 and 16.0x; no
  spin: 8.4 and 7.9x; the priority change + peer CPU without low latency 9.0x. main's best
  zenoh setting of session 16 (``--pin``) gave 1.6 / 1.4 / 1.6x at this load. ``--trace`` of
  the fast setting (load 11): ``up`` 68, ``ap_compute`` 98, ``down`` 10 us per step; thread
  CPU autopilot read 78 / step 29 / answer 29 / after 57 us, vehicle read 89, physics 18,
  sensors + encode 37, send 13 us; one involuntary switch per step per control thread (the
  reader taking the core for a moment).
- UDP is untouched (its processes have no zenoh threads): ``--spin-us 300 --pin --rt-priority
  10`` main / this tree in 5 interleaved pairs 21.9 / 19.2, 21.0 / 20.8, 22.1 / 21.4, 23.0 /
  20.9 (this tree first), 22.1 / 23.1x (this tree first); round trip median 81-92 us both,
  CPU per step 170-186 / 151-168 us both.
- Without flags nothing changed (main 0.9 / 1.3x against 1.9 / 4.4x at load 12-15: the
  load's noise); ``--zenoh-lowlatency`` alone 3.1 / 5.3x, CPU per step 478 / 446 us against
  558 / 484 us (autopilot). ``ZENOH_RUNTIME`` with one worker per runtime: 11.8 / 11.8x
  against 11.9 / 11.3x (no gain). The 100-byte floor (raw zenoh, two processes, unpinned):
  universal 43-114 us median, low-latency 30-43 us, unix-socket link 40 us, zenoh's UDP link
  47 us (no gain over TCP); UDP sockets' floor 15-17 us (session 13).
- ``vtolftc sitl --transport zenoh --spin-us 300 --cpus 0,1 --rt-priority 10
  --zenoh-lowlatency --zenoh-peer-cpu`` (40 s of case 1 with its run folder, load 3-5): 18.5x
  and 18.4x, roll / pitch / yaw RMSE 0.2325 / 0.6756 / 0.3053 deg (those of the docs); the
  processes' logs show every zenoh thread, also those started after the pinning, at priority
  11 on the other process's CPU. ``bench_sitl.py`` with the same flags, 20 s, load 4.1: 17.4x,
  round trip mean / median / p90 / p99 334 / 113 / 218 / 756 us, CPU per step 215 / 203 us.
- So zenoh reaches 15x on two cores that the two processes may hold (``SCHED_FIFO``, pinned,
  spinning); ~17x here under load, the idle machine to be measured. What is left between zenoh
  (median round trip ~120 us) and UDP (~85 us): the low-latency ``put`` (status + answer 58 us
  of wall / 29 us of CPU against UDP's 19 / 19) and the reader's hand-off per hop.

In-process (issue 24's second target, >= 150x real time per core, i.e. ~26 us per 4 ms
control step): ``benchmarks/bench_inproc.py`` (its docstring and ``--profile``): 155-161x on
the idle machine in session 14; after session 15's compiled outer loops, 4 interleaved pairs
of 120 s flights (load ~1.7, the host's noise +-20 % that hour) 119.8 / 162.9 / 140.3 /
150.9x against 143.7 / 138.7 / 109.8 / 125.1x before (per-step ratios 1.20, 0.85, 0.78,
0.83).

The lead's idle re-measure (main with zenoh-17 merged, 17:08 UTC, load 1.4-1.6, 20 s of case 1,
one flight each): ``--transport zenoh --spin-us 300 --pin --rt-priority 10 --zenoh-lowlatency
--zenoh-peer-cpu`` **19.0x** (round trip mean / median / p90 / p99 327 / 113 / 227 / 719 us;
CPU per step autopilot / vehicle 210 / 203 us): >= 15x met on two free cores; ``--transport
udp --spin-us 300 --pin --rt-priority 10`` 22.5x (279 / 89 / 172 / 619 us; 182 / 162 us).

Session 19 (main with session 18's physics, 2026-12-03 22:29-22:31 UTC, idle, load 1.1-1.3,
20 s of case 1, one flight each): ``--transport udp --spin-us 300 --pin --rt-priority 10``
**25.3x** (round trip mean / median / p90 / p99 280 / 74 / 186 / 474 us; CPU per step
autopilot / vehicle 158 / 145 us; ``autopilot_step`` 22 us, the vehicle's
``record_and_physics`` 10 us); zenoh with the same flags and ``--zenoh-lowlatency
--zenoh-peer-cpu`` **22.6x** (315 / 95 / 188 / 584 us; 175 / 170 us). Without flags: UDP
13.1x (413 / 190 / 321 / 895 us; 249 / 167 us), zenoh 7.5x (628 / 396 / 578 / 1709 us; 366
/ 289 us).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path
from typing import Any

from vtolftc.runners.scenario import paper_scenario, run_scenario
from vtolftc.runners.sitl import SitlConfig, run_sitl


def _in_process_step_cpu_us(scenario: object, controller: str) -> float:
    """Mean CPU time of ``Autopilot.step`` in an in-process flight [us] (thread CPU clock
    read around each call), the yardstick of the SITL process's ``step_cpu_mean_us``."""
    from vtolftc.firmware_sim.autopilot.autopilot import Autopilot

    step = Autopilot.step
    acc = [0.0, 0]

    def timed(self: Autopilot, nav: object) -> object:
        c0 = time.thread_time()
        u = step(self, nav)  # type: ignore[arg-type]
        acc[0] += time.thread_time() - c0
        acc[1] += 1
        return u

    Autopilot.step = timed  # type: ignore[assignment,method-assign]
    try:
        run_scenario(scenario, controller)  # type: ignore[arg-type]
    finally:
        Autopilot.step = step  # type: ignore[method-assign]
    return 1e6 * acc[0] / max(1, acc[1])


def _parts(n: int = 3000, reps: int = 5) -> None:
    """Thread CPU per call of the lockstep's per-step codec pieces, the compiled frame packer
    against the generated encoding in the same run, interleaved (warm caches: a lower bound
    of what they cost between two waits)."""
    import numpy as np

    from vtolftc.airframe.loader import load_airframe
    from vtolftc.firmware_sim.vehicle.battery import BatteryModel
    from vtolftc.firmware_sim.vehicle.model import Vehicle
    from vtolftc.firmware_sim.vehicle.state_encoder import StateEncoder
    from vtolftc.protocols.fastpack import FramePacker
    from vtolftc.protocols.hil import wire_commands
    from vtolftc.protocols.mavlink import SigningConfig, dialect, make_codec

    signing = SigningConfig(secret_key=bytes(range(32)))  # the SITL's HIL link is signed
    af = load_airframe()
    v = Vehicle(af)
    for _ in range(300):
        v.step(np.full(af.n_actuators, 0.3), 4)
    codec = make_codec(1, 191, signing=signing)
    enc = StateEncoder(v, BatteryModel(rho=af.air_density_kg_m3), codec, 10.0,
                       lambda: codec.heartbeat_encode(0, 0, 0, 0, 0), resign=True)
    ap = make_codec(1, 1, signing=signing)
    packer = FramePacker(ap, dialect().MAVLink_hil_actuator_controls_message)
    cmd = np.random.default_rng(0).uniform(-1.0, 1.0, af.n_actuators)
    u32 = np.zeros(16, dtype=np.float32)

    def answer_generated() -> None:
        u = wire_commands(cmd).tolist()
        u += [0.0] * (16 - len(u))
        ap.hil_actuator_controls_encode(123456, u, 128, 1).pack(ap)
        ap.seq = (ap.seq + 1) & 0xFF

    def answer_packer() -> None:
        u32[:cmd.size] = cmd
        packer.pack(123456, 1, *u32.tolist(), 128)

    s = v.sensors()

    def sensor_generated() -> None:
        a, g, m = s.accel_m_s2, s.gyro_rad_s, s.mag_gauss
        codec.hil_sensor_encode(4000, a[0], a[1], a[2], g[0], g[1], g[2], m[0], m[1], m[2],
                                s.abs_pressure_hpa, s.diff_pressure_hpa, s.pressure_alt_m,
                                s.temperature_c, 0x1FFF, 0).pack(codec)

    sensor_packer = FramePacker(codec, dialect().MAVLink_hil_sensor_message)

    def sensor_packed() -> None:
        sensor_packer.pack(4000, *s.accel_m_s2.tolist(), *s.gyro_rad_s.tolist(),
                           *s.mag_gauss.tolist(), s.abs_pressure_hpa, s.diff_pressure_hpa,
                           s.pressure_alt_m, s.temperature_c, 0x1FFF, 0)

    fns = (answer_generated, answer_packer, sensor_generated, sensor_packed, v.sensors,
           enc.datagram)
    res: dict[str, list[float]] = {f.__name__: [] for f in fns}
    for _ in range(reps):
        for f in fns:
            c0 = time.thread_time()
            for _ in range(n):
                f()
            res[f.__name__].append(1e6 * (time.thread_time() - c0) / n)
    res.update(_read_parts(v, enc, signing, n, reps))
    print(f"per call, thread CPU, min / median of {reps} x {n} (load "
          f"{os.getloadavg()[0]:.1f}): " + ", ".join(
              f"{k} {min(x):.1f} / {sorted(x)[len(x) // 2]:.1f} us" for k, x in res.items()))


def _read_parts(v: Any, enc: Any, signing: Any, n: int, reps: int) -> dict[str, list[float]]:
    """Thread CPU of the autopilot's read of one step's datagram (``HilBridge.drain``: parse,
    handle, decode) from an in-memory transport: the link's compiled scan (``read_fast``)
    against the generated parser alone (``read_generated``), interleaved."""
    from vtolftc.firmware_sim.autopilot.hil_bridge import HilBridge
    from vtolftc.protocols.link import Link
    from vtolftc.protocols.transport import LoopTransport

    class Generated:
        rejected = 0

        @staticmethod
        def parse(data: bytes) -> None:
            return None

    bridges = {}
    for name in ("read_fast", "read_generated"):
        link = Link(LoopTransport(), system_id=1, component_id=1, signing=signing)
        if name == "read_generated":
            link._fast = Generated()  # type: ignore[assignment]
        bridge = bridges[name] = HilBridge(link)
        bridge.home = (enc.home.lat_deg, enc.home.lon_deg, enc.home.alt_m)
    res: dict[str, list[float]] = {k: [] for k in bridges}
    for _ in range(reps):
        for name, bridge in bridges.items():
            grams = []
            for _ in range(n):  # fresh signing timestamps (a replay is dropped)
                v.time_usec += 4000
                grams.append(enc.datagram())
            tr = bridge.link.transport
            c0 = time.thread_time()
            for g in grams:
                tr.send_bytes(g)
                bridge.drain(0.0)
                bridge.take()
            res[name].append(1e6 * (time.thread_time() - c0) / n)
    return res


_FLOOR_MODES = ("zenoh-callback", "zenoh-channel", "ours-callback", "ours-channel", "udp")


def _floor_end(role: str, port: int, mode: str) -> tuple[Any, Any, Any]:
    """One end of the ping-pong: ``send(bytes)``, ``recv(timeout_s | None) -> bytes | None``
    (None: blocking), ``close()`` for ``mode`` (see :func:`_floor`)."""
    import queue

    if mode == "udp":
        import socket

        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", port if role == "ping" else port + 1))
        dest = ("127.0.0.1", port + 1 if role == "ping" else port)

        def recv_udp(timeout_s: float | None) -> bytes | None:
            sock.settimeout(timeout_s)
            try:
                return sock.recvfrom(2048)[0]
            except TimeoutError:
                return None

        return (lambda d: sock.sendto(d, dest)), recv_udp, sock.close
    ends = {"listen": [f"tcp/127.0.0.1:{port}"]} if role == "ping" else {
        "connect": [f"tcp/127.0.0.1:{port}"]}
    direction = "up" if role == "ping" else "down"
    if mode.startswith("ours-"):
        from vtolftc.protocols.zenoh_transport import ZenohTransport

        t = ZenohTransport("floor", "hil", direction, receive=mode[5:],
                           **ends)  # type: ignore[arg-type]

        def recv_ours(timeout_s: float | None) -> bytes | None:
            deadline = time.monotonic() + (5.0 if timeout_s is None else timeout_s)
            while time.monotonic() < deadline:
                got = t.recv_datagrams(max(0.0, deadline - time.monotonic()))
                if got:
                    return got[0]
            return None

        return t.send_bytes, recv_ours, t.close
    import zenoh

    from vtolftc.protocols.zenoh_transport import key_expr, zenoh_config

    session = zenoh.open(zenoh_config(**ends))  # type: ignore[arg-type]
    pub = session.declare_publisher(key_expr("floor", "hil", direction),
                                    congestion_control=zenoh.CongestionControl.BLOCK,
                                    reliability=zenoh.Reliability.RELIABLE, express=True)
    sub_key = key_expr("floor", "hil", "down" if role == "ping" else "up")
    if mode == "zenoh-callback":
        q: queue.SimpleQueue[bytes] = queue.SimpleQueue()
        session.declare_subscriber(sub_key, lambda smp: q.put(smp.payload.to_bytes()))

        def recv_cb(timeout_s: float | None) -> bytes | None:
            try:
                return q.get(timeout=5.0 if timeout_s is None else timeout_s)
            except queue.Empty:
                return None

        return pub.put, recv_cb, session.close
    sub = session.declare_subscriber(sub_key, zenoh.handlers.FifoChannel(256))

    def recv_channel(timeout_s: float | None) -> bytes | None:
        if timeout_s is None:
            return bytes(sub.recv().payload.to_bytes())
        deadline = time.monotonic() + timeout_s  # the hand-shake only: poll
        while time.monotonic() < deadline:
            smp = sub.try_recv()
            if smp is not None:
                return bytes(smp.payload.to_bytes())
            time.sleep(0.001)
        return None

    return pub.put, recv_channel, session.close


def _floor(n: int = 3000, port: int = 17550) -> None:
    """The links' floor: a ping-pong of 100-byte payloads between this process and a child
    (two processes as in SITL, loopback; zenoh in peer mode without scouting): raw zenoh with a
    Python callback + queue or with zenoh's FIFO channel, our ``ZenohTransport`` in either
    receive mode, raw UDP sockets (blocking). Round trip wall time and this process's CPU per
    round trip (every thread)."""
    import subprocess
    import sys

    for mode in _FLOOR_MODES:
        send, recv, close = _floor_end("ping", port, mode)
        child = subprocess.Popen([sys.executable, __file__, "--floor-pong", mode,
                                  "--floor-port", str(port)])
        try:
            payload = b"p" * 100
            deadline = time.monotonic() + 30.0
            while time.monotonic() < deadline:  # until the child answers
                send(payload)
                if recv(0.2) is not None:
                    break
            time.sleep(0.3)
            while recv(0.05) is not None:  # answers to the hand-shake's repeats
                pass
            rtt = []
            c0 = time.process_time()
            for _ in range(n):
                t0 = time.perf_counter()
                send(payload)
                recv(None)
                rtt.append(time.perf_counter() - t0)
            cpu = time.process_time() - c0
        finally:
            send(b"x")
            try:
                child.wait(timeout=10)
            except subprocess.TimeoutExpired:
                child.kill()
            close()
        r = sorted(rtt[n // 10:])
        print(f"{mode}: round trip median {1e6 * r[len(r) // 2]:.0f} us, p90 "
              f"{1e6 * r[int(0.9 * len(r))]:.0f} us, mean {1e6 * sum(r) / len(r):.0f} us; CPU "
              f"per round trip (this end) {1e6 * cpu / n:.0f} us; load "
              f"{os.getloadavg()[0]:.1f}", flush=True)
        port += 2


def _floor_pong(mode: str, port: int) -> None:
    """The child of :func:`_floor`: echo every payload until ``x`` (at most 120 s)."""
    import threading

    timer = threading.Timer(120.0, os._exit, (1,))  # never outlive a dead parent for long
    timer.daemon = True
    timer.start()
    send, recv, close = _floor_end("pong", port, mode)
    try:
        data = recv(30.0)
        while data is not None and data[:1] != b"x":
            send(data)
            data = recv(None)  # blocking, as in the ping's timed loop
    finally:
        time.sleep(0.2)
        close()


_SEGMENTS = ("ap_busy", "up", "ap_compute", "vehicle_busy", "down")


def _tail(out: Path, slow_us: float = 1000.0, hold_us: float = 50000.0) -> str:
    """The slow tail from both processes' step traces (``--trace``): each lockstep round trip
    (vehicle: from the start of the state's send to having read the controls) cut into
    ``ap_busy`` (the autopilot still in the previous step's after-answer work when the state
    left), ``up`` (until the autopilot has read and decoded it: the vehicle's send with the
    wake-up it runs, the autopilot's wake-up, GIL, read), ``ap_compute`` (read to answered:
    ``Autopilot.step``, the answer's send), ``vehicle_busy`` (the vehicle still in its
    after-send work when the answer left) and ``down`` (until the vehicle has read it); means
    over every step and over the slow ones (round trip > ``slow_us``; those > ``hold_us``
    are the simulation holds, left out), which part is the largest in each slow step, and
    the context switches and page faults per step of each control thread."""
    import numpy as np

    try:
        ap = dict(np.load(out / "autopilot" / "step_trace.npz"))
        ve = dict(np.load(out / "vehicle" / "step_trace.npz"))
    except OSError as exc:
        return f"    (no step trace: {exc})"
    j_of = {int(k): j for j, k in enumerate(ap["key"])}
    rows = []
    for i in range(1, len(ve["key"])):
        j = j_of.get(int(ve["key"][i]))
        if j is None or j == 0:
            continue
        s0 = ve["end_sensors_and_encode"][i - 1]
        ap_free = max(s0, ap["end_after_answer"][j - 1])
        read, ans = ap["end_wait_and_read"][j], ap["end_status_and_answer"][j]
        ve_free = max(ans, ve["end_after_send"][i - 1])
        end = ve["end_wait_and_read"][i]
        seg = (ap_free - s0, read - ap_free, ans - read, ve_free - ans, end - ve_free)
        sw = [ap[c][j] - ap[c][j - 1] for c in ("nivcsw", "nvcsw", "minflt")]
        sw += [ve[c][i] - ve[c][i - 1] for c in ("nivcsw", "nvcsw", "minflt")]
        cpu = [ap[f"cpu_{n}"][j] for n in ("wait_and_read", "autopilot_step",
                                           "status_and_answer", "after_answer")]
        rows.append((end - s0, *seg, *sw, *cpu))
    if not rows:
        return "    (no matching steps in the traces)"
    a = 1e6 * np.array(rows)
    a[:, 6:12] *= 1e-6  # counts, not seconds
    rtt = a[:, 0]
    keep = rtt < hold_us
    slow = keep & (rtt > slow_us)
    n, ns = int(keep.sum()), int(slow.sum())
    lines = [f"    tail (trace of {n} steps, {len(rtt) - n} holds left out): {ns} steps "
             f"({100 * ns / max(1, n):.1f} %) over {slow_us:.0f} us hold "
             f"{100 * rtt[slow].sum() / max(1e-9, rtt[keep].sum()):.0f} % of the round-trip "
             f"time; round trip mean {rtt[keep].mean():.0f} us, without them "
             f"{rtt[keep & ~slow].mean():.0f} us"]
    for label, m in (("all", keep), ("slow", slow)):
        if not m.any():
            continue
        seg = ", ".join(f"{k} {a[m, 1 + q].mean():.0f}" for q, k in enumerate(_SEGMENTS))
        sw = a[m, 6:12].mean(axis=0)
        cpu = a[m, 12:16].mean(axis=0)
        lines.append(f"      {label}: {seg} us; autopilot thread per step: involuntary / "
                     f"voluntary switches {sw[0]:.2f} / {sw[1]:.2f}, minor faults "
                     f"{sw[2]:.1f}, CPU read / step / answer / after {cpu[0]:.0f} / "
                     f"{cpu[1]:.0f} / {cpu[2]:.0f} / {cpu[3]:.0f} us; vehicle thread: "
                     f"switches {sw[3]:.2f} / {sw[4]:.2f}, minor faults {sw[5]:.1f}")
    if ns:
        top = np.bincount(np.argmax(a[slow, 1:6], axis=1), minlength=5)
        lines.append("      largest part of the slow steps: " + ", ".join(
            f"{k} {int(c)}" for k, c in zip(_SEGMENTS, top, strict=True)))
    return "\n".join(lines)


def _fly(args: argparse.Namespace, tr: str, scenario: object, tmp: str, spin_us: float,
         pin: bool) -> Any:
    """One SITL flight of the benchmark's configuration."""
    return run_sitl(SitlConfig(case=args.case, controller=args.controller, transport=tr,
                               duration_s=args.duration, out_dir=Path(tmp), plots=False,
                               spin_us=spin_us, rt_priority=args.rt_priority,
                               autopilot_cpu=0 if pin else -1, vehicle_cpu=1 if pin else -1,
                               trace_steps=100_000 if args.trace else 0,
                               zenoh_lowlatency=args.zenoh_lowlatency,
                               zenoh_peer_cpu=args.zenoh_peer_cpu and pin), scenario)


def _flags(args: argparse.Namespace, tr: str, spin_us: float, pin: bool) -> str:
    """The flight's configuration as this script's flags (one summary line's label)."""
    out = [f"--transport {tr}", f"--spin-us {spin_us:g}"]
    if pin:
        out.append("--pin")
    if args.rt_priority:
        out.append(f"--rt-priority {args.rt_priority}")
    if tr == "zenoh":
        out += [f for f, on in (("--zenoh-lowlatency", args.zenoh_lowlatency),
                                ("--zenoh-peer-cpu", args.zenoh_peer_cpu and pin)) if on]
    return " ".join(out)


def _summary(args: argparse.Namespace, tr: str, spin_us: float, pin: bool, res: Any) -> str:
    """One line: real-time factor, HIL round trip percentiles, CPU per step of each process
    (every thread), the load."""
    nan = float("nan")
    rtt = res.vehicle_summary.get("step_round_trip_us", {})
    return (f"summary [{_flags(args, tr, spin_us, pin)}]: {res.real_time_factor:.1f}x; round "
            "trip mean / median / p90 / p99 "
            + " / ".join(f"{rtt.get(q, nan):.0f}" for q in ("mean", "median", "p90", "p99"))
            + " us; CPU per step autopilot / vehicle "
            f"{res.autopilot_summary.get('cpu_per_step_us', nan):.0f} / "
            f"{res.vehicle_summary.get('cpu_per_step_us', nan):.0f} us; load "
            f"{os.getloadavg()[0]:.1f}")


def _matrix(args: argparse.Namespace, scenario: object) -> None:
    """One flight per configuration, ``--spin-us`` {0, 300} x pinned {off, on} (``--pin``:
    the autopilot on CPU 0, the vehicle on CPU 1), one summary line each."""
    transports = ("udp", "zenoh") if args.transport == "both" else (args.transport,)
    nan = float("nan")
    for tr in transports:
        for spin in (0.0, 300.0):
            for pin in (False, True):
                with tempfile.TemporaryDirectory(prefix=f"bench_sitl_{tr}_") as tmp:
                    res = _fly(args, tr, scenario, tmp, spin, pin)
                    rtt = res.vehicle_summary.get("step_round_trip_us", {})
                    print(f"{tr} spin {spin:3.0f} us pinned {'on ' if pin else 'off'} "
                          f"rt-priority {args.rt_priority}: {res.real_time_factor:5.1f}x; "
                          "round trip mean / median / p90 / p99 "
                          + " / ".join(f"{rtt.get(q, nan):.0f}"
                                       for q in ("mean", "median", "p90", "p99"))
                          + f" us; CPU per step autopilot / vehicle "
                          f"{res.autopilot_summary.get('cpu_per_step_us', nan):.0f} / "
                          f"{res.vehicle_summary.get('cpu_per_step_us', nan):.0f} us; load "
                          f"{os.getloadavg()[0]:.1f}", flush=True)
                    if args.trace:
                        print(_tail(Path(tmp)), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--transport", default="both", choices=("udp", "zenoh", "both"))
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--case", default="1")
    ap.add_argument("--controller", default="gs-shif")
    ap.add_argument("--spin-us", type=float, default=0.0,
                    help="busy-poll time of both processes before sleeping (default 0)")
    ap.add_argument("--pin", action="store_true",
                    help="pin the autopilot to CPU 0 and the vehicle to CPU 1 (--cpu)")
    ap.add_argument("--rt-priority", type=int, default=0,
                    help="both processes SCHED_FIFO at this priority (needs CAP_SYS_NICE)")
    ap.add_argument("--zenoh-lowlatency", action="store_true",
                    help="zenoh: the HIL link on zenoh's low-latency unicast transport")
    ap.add_argument("--zenoh-peer-cpu", action="store_true",
                    help="zenoh, pinned flights: each process's zenoh runtime threads on the "
                         "other process's CPU")
    ap.add_argument("--matrix", action="store_true",
                    help="one flight per --spin-us {0, 300} x pinned {off, on}, one line each "
                         "(no in-process reference)")
    ap.add_argument("--trace", action="store_true",
                    help="per-step traces of both processes: where the slow steps spend it")
    ap.add_argument("--parts", action="store_true",
                    help="only the per-call CPU of the HIL codec pieces (packer vs generated)")
    ap.add_argument("--floor", action="store_true",
                    help="only the links' floor: a 100-byte ping-pong between two processes")
    ap.add_argument("--floor-pong", choices=_FLOOR_MODES, help=argparse.SUPPRESS)
    ap.add_argument("--floor-port", type=int, default=17550, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.floor_pong:
        _floor_pong(args.floor_pong, args.floor_port)
        return
    if args.floor:
        _floor(port=args.floor_port)
        return
    if args.parts:
        _parts()
        return
    scenario = paper_scenario(args.case, args.duration)
    if args.matrix:
        _matrix(args, scenario)
        return

    t0 = time.perf_counter()
    ref = run_scenario(scenario, args.controller)
    wall = time.perf_counter() - t0
    print(f"in-process: {args.duration:g} s simulated in {wall:.2f} s "
          f"({args.duration / wall:.1f}x real time); autopilot "
          f"{1e6 * ref.timing_s['autopilot'] / (args.duration * 250):.0f} us/step, physics "
          f"{1e6 * ref.timing_s['physics'] / (args.duration * 250):.0f} us/step; "
          f"Autopilot.step CPU {_in_process_step_cpu_us(scenario, args.controller):.0f} us "
          "(mean, a second flight)")

    transports = ("udp", "zenoh") if args.transport == "both" else (args.transport,)
    print("\n| transport | real-time factor | flight wall (s) | HIL step round trip mean / "
          "median / p90 / p99 (us) | in autopilot, mean (us/step) | link + rest, mean "
          "(us/step) |")
    print("|---|---:|---:|---|---:|---:|")
    for tr in transports:
        with tempfile.TemporaryDirectory(prefix=f"bench_sitl_{tr}_") as tmp:
            res = _fly(args, tr, scenario, tmp, args.spin_us, args.pin)
            rtt = res.vehicle_summary.get("step_round_trip_us", {})
            steps = max(1, res.autopilot_summary.get("steps", 1))
            in_ap = 1e6 * res.autopilot_summary.get("wall_in_autopilot_s", 0.0) / steps
            sw = res.autopilot_summary.get("step_wall_us", {})
            nan = float("nan")
            mean = rtt.get("mean", nan)
            print(f"| {tr} | {res.real_time_factor:.1f}x | {res.flight_wall_s:.2f} | "
                  f"{mean:.0f} / {rtt.get('median', nan):.0f} / {rtt.get('p90', nan):.0f} / "
                  f"{rtt.get('p99', nan):.0f} | {in_ap:.0f} | {mean - in_ap:.0f} |")
            same = {k: (ref.metrics[k], res.metrics.get(k))
                    for k in ("rmse_altitude_m", "rmse_roll_deg")}
            print(f"    autopilot control step in the process: median {sw.get('median', nan):.0f}"
                  f" us, p99 {sw.get('p99', nan):.0f} us, CPU mean "
                  f"{res.autopilot_summary.get('step_cpu_mean_us', nan):.0f} us (step, status, "
                  f"answer); metrics (in-process, SITL): {same}")
            print(f"    CPU per step (every thread): autopilot process "
                  f"{res.autopilot_summary.get('cpu_per_step_us', nan):.0f} us, vehicle "
                  f"process {res.vehicle_summary.get('cpu_per_step_us', nan):.0f} us; load "
                  f"average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
            step_wall = 1e6 * res.flight_wall_s / steps
            print(f"    per step ({step_wall:.0f} us of wall time each), wall / thread CPU:")
            for who, summ in (("autopilot", res.autopilot_summary),
                              ("vehicle", res.vehicle_summary)):
                wall_parts = summ.get("part_mean_us", {})
                cpu_parts = summ.get("part_cpu_mean_us", {})
                print(f"      {who}: " + ", ".join(
                    f"{k} {x:.0f} / {cpu_parts.get(k, nan):.0f} us"
                    for k, x in wall_parts.items()))
            if args.trace:
                print(_tail(Path(tmp)))
            print(_summary(args, tr, args.spin_us, args.pin, res), flush=True)


if __name__ == "__main__":
    main()

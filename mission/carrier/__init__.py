"""The carrier-side controller (``marsupial carrier``): the paper's carrier law on a real or
simulated carrier robot.

Pure parts: :mod:`.modes` (what the carrier does, from the passenger's published phase),
:mod:`.guard` (the P3 guard: never closer to the target than ``b c - margin``, whatever the
passenger says; :mod:`.stopping`, where a heading robot can go while it stops), :mod:`.tracking` (a planar velocity command made into what a unicycle,
differential-drive or Ackermann robot can do), :mod:`.legs` (several targets), :mod:`.course`
(the recovery course), :mod:`.start` (the gentle start), :mod:`.acceleration` (its measured
acceleration), and :mod:`.step`, which puts them together into the carrier's one step (the
controller and the recovery simulation both run it). I/O: :mod:`.controller` (the loop), the robots it drives
(:mod:`.backends`: ``sim``, ``mavlink``, ``ros2``), and :mod:`.cli`.
"""

"""The paths a pixel-readout of the fast simulator can take, and their codes.

The code of a path indexes :data:`SIMULATION_PATHS`; each path family's
module (:mod:`.lazy`, :mod:`.interval`, :mod:`.window`, :mod:`.head`,
:mod:`.clock`) classifies and runs its own, :mod:`.plan` puts the
classifications together and ``SceneSimulator.readout`` dispatches them.
"""

#: The paths of :class:`tespike.golden.fastsim.SceneSimulator` (path codes index this tuple).
SIMULATION_PATHS = ("lazy", "event", "bright", "queue", "full", "head", "clock")
LAZY, EVENT, BRIGHT, QUEUE, FULL, HEAD, CLOCK = range(len(SIMULATION_PATHS))

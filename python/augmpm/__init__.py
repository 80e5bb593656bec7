"""augmpm: a material point method whose walls are right.

Load a scene, build a simulation, step it::

    import augmpm
    sim = augmpm.Simulation(augmpm.load_scene("scenes/dam_break.toml"), method="naive")
    sim.step(100)
    sim.positions  # (N, 2) numpy array, metres
"""

from augmpm._core import Error, SceneError, SimulationError, __version__
from augmpm.run import RunResult, run_scene
from augmpm.scene import Scene, Scene3, apply_override, load_scene
from augmpm.simulation import Simulation

__all__ = [
    "Error",
    "RunResult",
    "Scene",
    "Scene3",
    "SceneError",
    "Simulation",
    "SimulationError",
    "__version__",
    "apply_override",
    "load_scene",
    "run_scene",
]

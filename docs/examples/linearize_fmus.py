"""Linearize the plant FMU at hover and a controller FMU's sampled step
(docs/stability.md, "Linearizing any FMU"). Copy and run:

    python docs/examples/linearize_fmus.py [OUT_DIR]
"""
import sys

import numpy as np

from cosim.scenario import registry
from cosim.linearize.linearization import linearize_fmu, save_linearization
from fmu_models.models.quadrotor import hover_rotor_speed

out = sys.argv[1] if len(sys.argv) > 1 else "results/linearize-example"
models = registry.fmu_models()

# the plant (Model Exchange, directional derivatives), hovering 1 m up (z down)
omega = hover_rotor_speed()
plant = linearize_fmu(models["Quadrotor"].build(2), start={"z": -1.0, **{f"Omega_r_{i}": omega for i in range(1, 5)}},
                      inputs={f"Omega_{i}": omega for i in range(1, 5)})
print("plant:", plant.method, plant.system.nstates, "states; poles' largest real part",
      max(np.linalg.eigvals(plant.A).real))

# the PD controller's sampled step (Co-Simulation, one period), at rest at hover
controller = linearize_fmu(models["ControllerPD"].build(2), inputs={"z_ref": -1.0, "z": -1.0})
print("controller: dt =", controller.system.dt, "s,", controller.method, "error estimate",
      f"{controller.error_estimate:.2g}")

for path in save_linearization(plant, out, bode=[("Omega_1", "z")], stem="plant"):
    print(path)
for path in save_linearization(controller, out, stem="controller"):
    print(path)

"""Model Exchange FMUs solved together (cosim/fmi/me_system.py, me_system.c):
connected Model Exchange FMUs are one system, their connections evaluated
inside the right-hand side, both loops give the same rows bit for bit, an
algebraic loop between them is refused by name (exit 2)."""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from cosim.loop import kernel
from cosim.loop.connection import Connection, Endpoint
from cosim.errors import ConnectionCheckError
from cosim.fmi.fmu import FmuComponent
from cosim.loop.master import Master
from cosim.fmi.model_exchange import SolverSettings
from quadrotor_paper.cli import main
from tests.industrial_fmus import DC_MOTOR, DC_MOTOR_CONNECTIONS, algebraic_loop_specs, dc_motor_exact, dc_motor_specs

REFERENCE = Path(__file__).resolve().parents[2].parent / "shared" / "reference-fmus"
pytestmark = pytest.mark.skipif(not REFERENCE.is_dir(), reason=f"the Reference FMUs are not at {REFERENCE}")
THROUGH = "Float64_continuous_input", "Float64_continuous_output"


@pytest.mark.parametrize("version", [2, 3])
def test_connected_model_exchange_fmus_are_one_system_run_alike_by_both_loops(monkeypatch, version):
    """VanDerPol feeding Feedthrough, both Model Exchange: one system of two
    (the connection set inside its right-hand side, not by the master), the
    compiled loop calls it in C, and its rows are the Python loop's to the
    bit; Feedthrough's output is the oscillator's state at every row, through
    the connection's conversion (factor 2, offset 1: a unit conversion)."""
    def build() -> Master:
        fmus = [FmuComponent("V", REFERENCE / f"fmi{version}" / "VanDerPol.fmu", interface="ModelExchange",
                             solver=SolverSettings(relative_tolerance=1e-8)),
                FmuComponent("F", REFERENCE / f"fmi{version}" / "Feedthrough.fmu", interface="ModelExchange")]
        converted = Connection(Endpoint("V", "x0"), Endpoint("F", THROUGH[0]), conversion=(2.0, 1.0))
        return Master(fmus, [], [converted], 0.1, ["V.x0", f"F.{THROUGH[1]}"])

    runs = []
    for compiled in (True, False):
        monkeypatch.setenv("COSIM_PYTHON_LOOP", "" if compiled else "1")
        kernel.load.cache_clear()
        with build() as master:
            assert [[m.name for m in s.members] for s in master.me_systems] == [["V", "F"]]
            assert master.plan.fmus[1].inputs == () and not master.plan.python_calls
            runs.append(master.run(2.0))
    kernel.load.cache_clear()
    fast, slow = runs
    assert not fast.python_loop and slow.python_loop
    np.testing.assert_array_equal(fast.data, slow.data)
    np.testing.assert_array_equal(fast[f"F.{THROUGH[1]}"], 2.0 * fast["V.x0"] + 1.0)
    assert np.ptp(fast["V.x0"]) > 1  # the oscillator ran


def test_an_algebraic_loop_between_model_exchange_fmus_is_refused_by_its_path(tmp_path, capsys):
    path = json.dumps(str(REFERENCE / "fmi2" / "Feedthrough.fmu"))
    scenario = tmp_path / "loop.toml"
    scenario.write_text(f'connections = ["a.{THROUGH[1]} -> b.{THROUGH[0]}", "b.{THROUGH[1]} -> a.{THROUGH[0]}"]\n'
                        f'[simulation]\nduration = 1.0\nstep = 0.1\n'
                        f'[fmus.a]\npath = {path}\ninterface = "ModelExchange"\n'
                        f'[fmus.b]\npath = {path}\ninterface = "ModelExchange"\n')
    assert main(["run", str(scenario), "--out", str(tmp_path / "out"), "--no-plots", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert (f"algebraic loop between Model Exchange FMUs: a.{THROUGH[1]} -> b.{THROUGH[0]} -> b.{THROUGH[1]} -> "
            f"a.{THROUGH[0]};") in err


def test_a_member_s_state_events_stop_the_shared_integration():
    """BouncingBall feeding Feedthrough, one system: the ball's bounces (its
    event indicator, among the system's roots) stop the shared integration
    and its event iteration runs there; the ball's height is that of the ball
    integrated alone, to the bit, and Feedthrough passes it on at every row."""
    def fly(fmus, connections) -> np.ndarray:
        with Master(fmus, [], connections, 0.05, ["B.h"] + ([f"F.{THROUGH[1]}"] if connections else [])) as master:
            return master.run(3.0).data

    ball = lambda: FmuComponent("B", REFERENCE / "fmi2" / "BouncingBall.fmu", interface="ModelExchange",  # noqa: E731
                                solver=SolverSettings(relative_tolerance=1e-8))
    together = fly([ball(), FmuComponent("F", REFERENCE / "fmi2" / "Feedthrough.fmu", interface="ModelExchange")],
                   [f"B.h -> F.{THROUGH[0]}"])
    alone = fly([ball()], [])
    np.testing.assert_array_equal(together[:, :2], alone)
    np.testing.assert_array_equal(together[:, 2], together[:, 1])
    assert np.sum(np.diff(np.sign(np.diff(alone[:, 1]))) > 0) >= 2  # it bounced (the height turned upwards)


def test_the_solver_s_failure_is_told_in_one_line_with_cvode_s_own_words():
    """Dahlquist with k = NaN: CVODE cannot converge; the run fails naming the
    FMU, the time, CVODE's flag and its message (no print of SUNDIALS's own)."""
    fmu = FmuComponent("D", REFERENCE / "fmi2" / "Dahlquist.fmu", interface="ModelExchange")
    with Master([fmu], [], [], 0.1, ["D.x"], fmu_parameters={"D": {"k": float("nan")}}) as master:
        result = master.run(1.0, raise_on_error=False)
    assert result.status == "failed" and len(result.error.splitlines()) == 1
    assert result.error.startswith("D (") and "Model Exchange integration (cvode)" in result.error
    assert "CVODE failed (CV_CONV_FAILURE, flag -4): " in result.error and "corrector convergence" in result.error


def test_members_of_one_system_take_one_solver_method_or_are_coupled_loosely():
    def build(coupling: str) -> Master:
        fmus = [FmuComponent("V", REFERENCE / "fmi2" / "VanDerPol.fmu", interface="ModelExchange"),
                FmuComponent("F", REFERENCE / "fmi2" / "Feedthrough.fmu", interface="ModelExchange",
                             solver=SolverSettings("euler"))]
        return Master(fmus, [], [f"V.x0 -> F.{THROUGH[0]}"], 0.1, coupling=coupling)

    with pytest.raises(ConnectionCheckError, match=r"one solver method \(V: cvode, F: euler\)"):
        build("tight")
    with build("loose") as master:
        assert [len(s.members) for s in master.me_systems] == [1, 1]


# the mechanical part's partial derivatives (tests/industrial_fmus.py gives the electrical part's)
MECHANICAL_PARTIALS = """    if (unknown == VR_der_x_1 && known == VR_x_2) return 1;
    if (unknown == VR_der_x_2 && known == VR_flange_tau) return 1 / J;
    if (unknown == VR_der_x_2 && known == VR_x_2) return -b / J;
    if (unknown == VR_w && known == VR_x_2) return 1;
    if (unknown == VR_phi && known == VR_x_1) return 1;"""


def _dc_motor(industrial_fmus, directional: bool = False) -> tuple[dict[str, Path], list[Connection]]:
    """The DC motor's three FMUs (tests/industrial_fmus.py; Model Exchange and Co-Simulation; with
    ``directional`` the mechanical part gives its directional derivatives too), built once per test
    process (the ``industrial_fmus`` fixture), and their connections (the mechanical part writes
    rad/s without the radian, as many tools do: one unit, docs/fmi-support.md "Angles")."""
    specs = dc_motor_specs(interfaces=("ModelExchange", "CoSimulation"))
    if directional:
        specs["DCMotor_Mechanical"] = dataclasses.replace(specs["DCMotor_Mechanical"], partials=MECHANICAL_PARTIALS)
    fmus = {n: industrial_fmus(s) for n, s in specs.items()}
    return fmus, [Connection(Endpoint(a, x), Endpoint(b, y)) for (a, x), (b, y) in DC_MOTOR_CONNECTIONS]


def test_the_dc_motor_as_three_coupled_model_exchange_fmus_is_the_monolithic_solution(industrial_fmus):
    """A voltage source, the motor's electrical part and its mechanical part,
    three Model Exchange FMUs in a feedback loop through their states: one
    system lands within 1e-6 of the monolithic solution (scipy's solve_ivp
    over the stacked states, rtol 1e-10: the speed, about 200 rad/s, and the
    current); each FMU alone with its inputs held over a step (coupling =
    "loose") and their Co-Simulation are visibly off. At a 3 ms step the
    source's time event (10 ms) falls inside a step: it stops the shared
    integration there, and the states right after it are right."""
    paths, connections = _dc_motor(industrial_fmus)
    step = 3e-3

    def fly(interface: str, coupling: str = "tight"):
        solver = SolverSettings(relative_tolerance=1e-10) if interface == "ModelExchange" else None
        fmus = [FmuComponent(n, p, interface=interface, solver=solver) for n, p in paths.items()]
        with Master(fmus, [], connections, step, ["DCMotor_Mechanical.w", "DCMotor_Electrical.i"],
                    coupling=coupling) as master:
            return master.run(0.06)

    tight = fly("ModelExchange")
    exact = dc_motor_exact(tight.time)  # [i, phi, w]
    assert np.max(np.abs(tight["DCMotor_Mechanical.w"] - exact[:, 2])) < 1e-6
    assert np.max(np.abs(tight["DCMotor_Electrical.i"] - exact[:, 0])) < 1e-6
    after = np.searchsorted(tight.time, DC_MOTOR["t_step"], side="right")  # the first row after the step
    assert abs(tight["DCMotor_Mechanical.w"][after] - exact[after, 2]) < 1e-7 and exact[after, 2] > 1.0
    for loose in (fly("ModelExchange", "loose"), fly("CoSimulation")):
        assert np.max(np.abs(loose["DCMotor_Mechanical.w"] - exact[:, 2])) > 0.05


def test_cvode_s_jacobian_from_the_members_directional_derivatives_through_the_connections(industrial_fmus):
    """jacobian = "directional": CVODE's Newton matrix from the electrical
    and mechanical parts' directional derivatives, by the chain rule through
    the connections (the torque into the mechanical part, the speed back):
    the Jacobian CVODE is given is the stacked model's (the couplings -k/L
    and k/J come through the connections), the run lands within 1e-6 of the
    monolithic solution, and is another run than the one with CVODE's
    difference quotients. A member without directional derivatives is
    refused in one line."""
    def fly(paths, connections, jacobian: str):
        fmus = [FmuComponent(n, p, interface="ModelExchange",
                             solver=SolverSettings(relative_tolerance=1e-10, jacobian=jacobian))
                for n, p in paths.items()]
        with Master(fmus, [], connections, 3e-3, ["DCMotor_Mechanical.w"]) as master:
            return master.run(0.06)

    paths, connections = _dc_motor(industrial_fmus, directional=True)
    directional, difference = fly(paths, connections, "directional"), fly(paths, connections, "difference")
    fmus = [FmuComponent(n, p, interface="ModelExchange", solver=SolverSettings(jacobian="directional"))
            for n, p in paths.items()]
    with Master(fmus, [], connections, 3e-3) as master:  # the Jacobian after the step, against the stacked one
        master.run(0.012)
        system, p = master.me_systems[0], DC_MOTOR  # stacked states: [i], [phi, w]
        np.testing.assert_allclose(system.jacobian(0.012), [[-p["R"] / p["L"], 0, -p["k"] / p["L"]], [0, 0, 1],
                                                           [p["k"] / p["J"], 0, -p["b"] / p["J"]]], rtol=1e-14)
    exact = dc_motor_exact(directional.time)
    assert np.max(np.abs(directional["DCMotor_Mechanical.w"] - exact[:, 2])) < 1e-6
    assert not np.array_equal(directional.data, difference.data)
    with pytest.raises(ConnectionCheckError, match=r'jacobian = "directional": DCMotor_Mechanical provide\(s\) no '):
        fly(*_dc_motor(industrial_fmus), "directional")


def test_the_jacobian_s_chain_rule_passes_through_a_member_with_direct_feedthrough(industrial_fmus):
    """A gain of 0.8 with direct feedthrough and no state (``GainA``: y = K[1,1] u) put between the
    motor's torque and its mechanical part: one system of four members, and the Jacobian CVODE is
    given carries the gain through the feedthrough, d(der w)/d(i) = 0.8 k / J, the rest the motor's."""
    paths, _ = _dc_motor(industrial_fmus, directional=True)
    paths["Gain"] = industrial_fmus(algebraic_loop_specs(a=0.8, c=0.0, interfaces=("ModelExchange",))["GainA"])
    connections = ["DCMotor_Source.v -> DCMotor_Electrical.pin_p.v", "DCMotor_Electrical.flange.tau -> Gain.u",
                   "Gain.y -> DCMotor_Mechanical.flange.tau", "DCMotor_Mechanical.w -> DCMotor_Electrical.w"]
    fmus = [FmuComponent(n, p, interface="ModelExchange", solver=SolverSettings(jacobian="directional"))
            for n, p in paths.items()]
    with Master(fmus, [], connections, 3e-3) as master:
        master.run(0.012)
        system, p = master.me_systems[0], DC_MOTOR
        assert len(system.members) == 4
        np.testing.assert_allclose(system.jacobian(0.012), [[-p["R"] / p["L"], 0, -p["k"] / p["L"]], [0, 0, 1],
                                                           [0.8 * p["k"] / p["J"], 0, -p["b"] / p["J"]]], rtol=1e-14)

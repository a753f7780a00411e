"""Tests test public behaviour; a test that imports a private module of jaxfdi is the exception,
and says why here. Every private module a test imports has its reason below (a new one fails
until it is given one, a reason nobody needs any more fails too), so the exceptions stay few
and deliberate. A private module whose objects the public API exports is imported from there
(``from jaxfdi.gnss import raim_fdi``, not ``from jaxfdi.gnss._integrity import raim_fdi``)."""

import ast
import pathlib

TESTS = pathlib.Path(__file__).resolve().parents[1]

#: the malformed-call table covers every function of these modules, public or not
_EVERY_FUNCTION = (
    "test_malformed_calls enumerates every function of the module, private ones included"
)

#: private module -> why tests import it
WHY = {
    "jaxfdi._simulation.faults": "the faults' per-step pieces (apply_fault, active_label) the simulator composes, "
    "tested alone where an onset or a sign error shows directly",
    "jaxfdi._studies.frame": "results_html, a frame as the notebooks show it (a table per group, escaping)",
    "jaxfdi._io.files": "the provenance writer every CLI command must go through (a structural test)",
    "jaxfdi._numerics.levenberg_marquardt": "the solver under the trim and the least-squares fixes, against "
    "SciPy on its own problems",
    "jaxfdi._numerics.linalg": "the written-out factorisations against LAPACK, batched or not",
    "jaxfdi._simulation.loop": "the closed loop's step functions, driven one step at a time",
    "jaxfdi._studies.metrics": "the record's per-step updates and interval helpers behind the studies' rates, "
    "against brute force",
    "jaxfdi._simulation.monitor": "filter_detector, the monitor's fused step, against the filter and the detector "
    "run apart",
    "jaxfdi._studies.montecarlo": "the run keys and chunking the study engine relies on (equal results over "
    "processes and chunk sizes)",
    "jaxfdi._io.progress": "the progress line's behaviour under logging and compilation",
    "jaxfdi._numerics.riccati": "the information form of the Riccati solver beside the public one",
    "jaxfdi._simulation.stages": "the stage shapes the F-16 loop composes, checked stage by stage",
    "jaxfdi._studies.study": "the study engine's slicing of cases and compiled-program sharing",
    "jaxfdi.control._attitude": "the wheels' torque allocation against its closed-form pseudo-inverse",
    "jaxfdi.control._eigenstructure": "the gain schedule's interpolation and the effectiveness input, "
    "against a fresh eigenstructure assignment",
    "jaxfdi.control._f16_loop": _EVERY_FUNCTION,
    "jaxfdi.control._flight": _EVERY_FUNCTION,
    "jaxfdi.detection._chi2": "the NIS of one step, the building block of every chi-square test",
    "jaxfdi.detection._credits": "the credit isolator, used only by the wheels' FDI, tested as a detector",
    "jaxfdi.detection._dual_filter": "det A, the credits' score, against finite differences",
    "jaxfdi.detection._glrt": "the GLR statistic by onset against the brute-force maximisation",
    "jaxfdi.detection._glrt_transient": "the transient signatures against the recursion written out",
    "jaxfdi.detection._hybrid_psa": "the hybrid parity/UKF rule's internals beside the F-16 study",
    "jaxfdi.detection._known_change": "the known-change GLR/CUSUM bank, the engine's limit reference",
    "jaxfdi.detection._noncentral_chi2": "the non-central chi-square CDF and quantile against SciPy",
    "jaxfdi.detection._parity": "the parity space's matrices against their defining identities",
    "jaxfdi.detection._sensor_configuration": "the sensor-layout metrics against brute force",
    "jaxfdi.detection._signature": "the signature matching against brute force",
    "jaxfdi.detection._wavelet": "the detail sigma from the sample variance, the paper's rule",
    "jaxfdi.filters._driver": "which path run_filter takes (the batch kernel, the covariance probe)",
    "jaxfdi.filters._sqrt_kalman": "the square-root state's factor against the covariance filter's",
    "jaxfdi.filters._time_varying": "the time-varying model's per-step slice",
    "jaxfdi.filters._tskf": "the two-stage filter's internals against the augmented-state filter",
    "jaxfdi.gnss._android": "the ground-truth reader of the phone traces",
    "jaxfdi.gnss._frames": "frame helpers (elevation, NED) against closed forms, and "
    + _EVERY_FUNCTION,
    "jaxfdi.gnss._integrity": "the geometry of one fix, and " + _EVERY_FUNCTION,
    "jaxfdi.gnss._measurements": _EVERY_FUNCTION,
    "jaxfdi.gnss._orbits": "the orbit's pieces (clock, velocity, transmission time) against RTKLIB's "
    "formulas, and " + _EVERY_FUNCTION,
    "jaxfdi.gnss._paths": _EVERY_FUNCTION,
    "jaxfdi.gnss._positioning": "the DOPs against their definition, and " + _EVERY_FUNCTION,
    "jaxfdi.gnss._protection": _EVERY_FUNCTION,
    "jaxfdi.gnss._raim": "the parity matrix and the paper's threshold, and " + _EVERY_FUNCTION,
    "jaxfdi.gnss._receiver": "the receiver's error model (code sigma, URA) against the ICD's tables",
    "jaxfdi.gnss._rinex": "the RINEX parser on malformed text, and " + _EVERY_FUNCTION,
    "jaxfdi.gnss._rinex_obs": "the RINEX observation parser on malformed text",
    "jaxfdi.gnss._solution_separation": "the simplified solution separation and its constants, against "
    "every mode enumerated",
    "jaxfdi.gnss._yuma": "the almanac parser on malformed text, and " + _EVERY_FUNCTION,
    "jaxfdi.ins._earth": "the WGS-84 radii and gravity against closed forms",
    "jaxfdi.ins._error_state": "the error-state matrices against finite differences, and "
    + _EVERY_FUNCTION,
    "jaxfdi.ins._imu": "the IMU grades and error model, and " + _EVERY_FUNCTION,
    "jaxfdi.ins._integrity": _EVERY_FUNCTION,
    "jaxfdi.ins._loosely_coupled": "the filter's update and predict apart, and " + _EVERY_FUNCTION,
    "jaxfdi.ins._mechanization": "the strapdown step against closed-form motions, and "
    + _EVERY_FUNCTION,
    "jaxfdi.ins._plant": "the simulated IMU and GPS the INS study flies",
    "jaxfdi.ins._scst": "the SCST's propagators, and " + _EVERY_FUNCTION,
    "jaxfdi.ins._trajectory": "the reference trajectories against closed forms, and "
    + _EVERY_FUNCTION,
    "jaxfdi.models._engine": "the engine's constants (sample time, output names) the tests size by",
    "jaxfdi.models._integrate": "the RK4 step against closed forms, unrolled and looped",
    "jaxfdi.models._reaction_wheels": "the pyramid geometry and rate Jacobian against finite differences",
    "jaxfdi.models._rigid_body": "the rigid-body problem the nonlinear filters are checked on",
    "jaxfdi.models._vtol": "the VTOL's matrices as the paper prints them",
    "jaxfdi.models.f16._aero": "the book's aerodynamic tables against its printed values",
    "jaxfdi.models.f16._book": "the book's trim cases",
    "jaxfdi.models.f16._dynamics": "the aerodynamic coefficients and saturations against the book, and "
    + _EVERY_FUNCTION,
    "jaxfdi.models.f16._engine": "the engine model (thrust, power rate, throttle gearing) against the book",
    "jaxfdi.models.f16._linearize": "the longitudinal linearisation against the book's",
    "jaxfdi.models.f16._morelli": "Morelli's polynomial coefficients against his tables",
    "jaxfdi.models.f16._plant": "the measured states and the skewed rate axes of the sensor layout",
    "jaxfdi.models.f16._rates": "the rate derivative against finite differences",
    "jaxfdi.models.f16._tables": "the table lookups against the book's interpolation",
    "jaxfdi.models.f16._trim": "the trim residuals and conditions against the book's trims",
    "jaxfdi.scenarios.gnss_real._peer_navdata": "the peers' navigation data the phone study compares with",
    "jaxfdi.scenarios.gnss_real._peer_row": "the peers' rows the phone study compares with",
    "jaxfdi.tuning._parameterize": _EVERY_FUNCTION,
}


def _is_module(dotted: str) -> bool:
    path = TESTS.parent.joinpath(*dotted.split("."))
    return path.with_suffix(".py").exists() or (path / "__init__.py").exists()


def _private_imports() -> dict[str, set[str]]:
    """Private jaxfdi module -> the test files importing it (``from ... import`` or ``import``)."""
    found: dict[str, set[str]] = {}
    for path in TESTS.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            modules = []
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("jaxfdi"):
                if any(part.startswith("_") for part in node.module.split(".")):
                    # ``from jaxfdi._io import files`` imports the module ``jaxfdi._io.files``
                    modules += [
                        f"{node.module}.{a.name}"
                        if _is_module(f"{node.module}.{a.name}")
                        else node.module
                        for a in node.names
                    ]
                else:  # a private module (or name) of a public package
                    modules += [
                        f"{node.module}.{a.name}" for a in node.names if a.name.startswith("_")
                    ]
            elif isinstance(node, ast.Import):
                modules += [a.name for a in node.names if a.name.startswith("jaxfdi.")]
                modules = [m for m in modules if any(p.startswith("_") for p in m.split("."))]
            for module in modules:
                found.setdefault(module, set()).add(path.name)
    return found


def test_every_private_module_a_test_imports_says_why():
    found = _private_imports()
    missing = sorted(set(found) - set(WHY))
    assert not missing, {m: sorted(found[m]) for m in missing}
    stale = sorted(set(WHY) - set(found))
    assert not stale, f"no test imports these any more: {stale}"

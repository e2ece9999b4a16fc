"""Shared fixtures. Real data is read from ``../shared/data`` beside the checkout."""

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
#: ``../shared/data`` beside the checkout, or the folder in ``HANDCAP_SHARED_DATA``.
SHARED_DATA = Path(os.environ.get("HANDCAP_SHARED_DATA") or REPO.parent / "shared" / "data")


#: Test modules whose tests share an expensive fixture (seconds to build: a rendered session, a trained model),
#: by group: with pytest-xdist (``make test``) each group runs on one worker, so its fixtures are built once; the
#: other tests are shared out one at a time. (pytest-xdist's own ``xdist_group`` marks are ignored under pytest 9.2,
#: pytest-dev/pytest-xdist#1386.)
SHARED_FIXTURE_GROUPS = {
    **dict.fromkeys(("tests/occlusion/test_fill.py", "tests/occlusion/test_filler.py", "tests/occlusion/test_train.py"),
                    "glove-model"),
    **dict.fromkeys(("tests/solve/test_motion.py", "tests/solve/test_calibration.py",
                     "tests/solve/test_positionless.py", "tests/solve/test_lm.py"), "solve-sessions"),
    **{module: module for module in (
        "tests/session/test_session.py", "tests/solve/test_relabel.py", "tests/stream/test_stream.py",
        "tests/labeling/test_adapt.py", "tests/labeling/test_synthetic.py", "tests/labeling/test_fingers.py",
        "tests/labeling/test_cli_label.py", "tests/multiview/test_calibration.py", "tests/objects/test_cube_label.py",
        # module fixtures of 1-4 s that were built on both workers when the module's tests were shared out
        "tests/report/test_html.py", "tests/synth/test_scene.py", "tests/multiview/test_reconstruct.py",
        "tests/detect/test_pyramid.py", "tests/solve/test_cli_solve.py", "tests/multiview/test_clean.py",
        "tests/markerless/test_grasp.py", "tests/markerless/test_contact.py", "tests/test_cli_bad_input.py",
        # a rendered, detected take of 8 cameras (10 s), built on both workers before
        "tests/detect/test_seek.py",
        # rendered sheets and their readings (3.5 s), a labelled take, takes solved with their swaps (1-3 s each)
        "tests/detect/test_adapt.py", "tests/labeling/test_release.py", "tests/stream/test_live_swaps.py",
        "tests/solve/test_swaps.py")},
}


#: The units of work (a group of :data:`SHARED_FIXTURE_GROUPS`, else one test) that took 8 s or more on the 2-core
#: VM, slowest first (``--durations=0``, summed over each group). They are handed out before the others, so that the
#: run ends on short tests: in collection order, the 46 s images demo started last but one and the other worker
#: waited 30 s for it at the end. A name missing here (renamed, or a new slow test) only costs that wait again.
#: Left out on purpose: ``tests/stream/test_stream.py`` (27 s), whose benchmark run starts a new Python; handed out
#: first, that process compiled the solver's numba kernels again while the workers were compiling them (21 s in a
#: fresh clone's CI against 9 s once the workers have cached them).
SLOW_FIRST = (
    "tests/session/test_session.py",
    "tests/test_demo_images.py::test_demo_from_images_runs_every_stage_and_scores_it",
    "glove-model", "solve-sessions", "tests/multiview/test_calibration.py",
    "tests/detect/test_pyramid.py", "tests/solve/test_relabel.py",
    "tests/occlusion/test_generalise.py::test_augmentation_generalises_from_synthetic_hands_to_the_real_glove",
    "tests/labeling/test_adapt.py",
    "tests/detect/test_adapt.py",
    "tests/detect/test_capture.py::test_cameras_in_processes_or_on_dask_give_the_same_detections",
    "tests/markerless/test_grasp.py", "tests/labeling/test_fingers.py",
    "tests/objects/test_cube_track.py::test_four_camera_synthetic_takes_read_right_or_say_so",
    "tests/labeling/test_cli_label.py",
    "tests/detect/test_seek.py", "tests/detect/test_real_images.py::test_real_images_without_patches_read_no_tag",
    "tests/detect/test_refine.py::test_training_command_writes_weights_and_starts_from_others",
    "tests/report/test_html.py", "tests/synth/test_scene.py",
    "tests/synth/test_images.py::test_a_held_object_wears_its_patches_and_the_detector_names_them",
    "tests/test_imports.py::test_every_subpackage_imports_alone",
    "tests/detect/test_checker.py::test_the_training_command_fits_a_checker_from_new_scenes",
    "tests/labeling/test_synthetic.py",
)


def work_unit_rank(scope: str) -> int:
    """Where a unit of work comes in the order it is handed out: its place in :data:`SLOW_FIRST`, else after all
    of them."""
    try:
        return SLOW_FIRST.index(scope)
    except ValueError:
        return len(SLOW_FIRST)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """pytest-xdist's ``load`` scheduling, except that each of :data:`SHARED_FIXTURE_GROUPS` is one unit of work
    and the units of :data:`SLOW_FIRST` are handed out first."""
    if config.getvalue("dist") not in ("load", "loadgroup"):
        return None
    from xdist.scheduler import LoadScopeScheduling

    class SharedFixtureGroups(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return SHARED_FIXTURE_GROUPS.get(nodeid.split("::", 1)[0], nodeid)

        def _assign_work_unit(self, node) -> None:
            # The queue's slowest unit to the front (the first of equals, so the rest keep xdist's order).
            self.workqueue.move_to_end(min(self.workqueue, key=work_unit_rank), last=False)
            super()._assign_work_unit(node)

    return SharedFixtureGroups(config, log)


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The folder of real recordings (``../shared/data``); CI has it beside the checkout.

    Tests that need it are skipped, saying why, where it is absent (README, "Test data").
    """
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data folder {SHARED_DATA} is absent: put the shared data beside the checkout "
                    "(../shared/data) or set HANDCAP_SHARED_DATA; see README, 'Test data'")
    return SHARED_DATA


@pytest.fixture(scope="session")
def real_glove(shared_data):
    """The real Qualisys glove recording (its glove-13 markers, 6,000 frames at 100 Hz) and the attachment
    calibrated on its first 1,000 frames: ``(MarkerSequence, MarkerAttachment)``."""
    import warnings

    from handcap.core.errors import HandcapWarning
    from handcap.io import read_markers
    from handcap.layouts import load_layout
    from handcap.solve import calibrate_attachment

    layout = load_layout("glove-13")
    take = read_markers(shared_data / "markers/hand_embodiment_glove/recording.tsv").select(layout.names)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HandcapWarning)
        return take, calibrate_attachment(take.frames(0, 1000), layout).attachment


@pytest.fixture(scope="session")
def gl_ok():
    """Skip, saying why, where the renderer cannot run: no moderngl (extra 'images') or no headless OpenGL."""
    pytest.importorskip("moderngl", reason="the renderer needs moderngl (extra 'images')")
    from handcap import HandcapError
    from handcap.synth.images import _context
    try:
        _context().release()
    except HandcapError as err:
        pytest.skip(f"no headless OpenGL here: {err}")


# Tests that read ../shared/data carry the ``realdata`` marker (``-m "not realdata"`` leaves them out), and with
# HANDCAP_REQUIRE_REALDATA set (.ci/run sets it) a run in which none of them ran fails: a CI that skipped them all,
# for a moved folder or a mistyped path, would otherwise pass without ever reading a real recording.
REQUIRE_REALDATA = "HANDCAP_REQUIRE_REALDATA"
_ran_realdata: list = []
_failures: list = []


def pytest_collection_modifyitems(config, items):
    for item in items:
        if "shared_data" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.realdata)


_seen_realdata: list = []


def pytest_runtest_logreport(report):
    # Reports reach this hook in the process that runs the tests and, with pytest-xdist, in the controller
    # too (keywords included), so the check below works either way.
    if "realdata" in report.keywords:
        _seen_realdata.append(report.nodeid)
        if report.when == "call":
            _ran_realdata.append(report.nodeid)


def pytest_sessionfinish(session, exitstatus):
    if not os.environ.get(REQUIRE_REALDATA) or session.testscollected == 0:
        return
    if hasattr(session.config, "workerinput"):
        return  # a pytest-xdist worker: the controller, which sees every report, checks
    if not _seen_realdata:
        return  # deselected on purpose (-m "not realdata", -k, a single file)
    if not _ran_realdata:
        _failures.append(f"{REQUIRE_REALDATA} is set but no real-data test ran: the folder {SHARED_DATA} is absent "
                         "or unreadable (see README, 'Test data')")
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def pytest_terminal_summary(terminalreporter):
    for line in _failures:
        terminalreporter.write_line(line, red=True)

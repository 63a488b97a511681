"""Progress of compress (socbjax._progress): the 'compiling …' line, the per-phase reports with
displacement, force and steps, and chunks of adaptive length that change nothing in the path
and reuse one compiled program."""

import io
import time

import numpy as np

import socbjax as sj
from socbjax._progress import Progress


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def _column():
    return sj.column(5, supports=("clamped", "pinned"), dim=2)


def test_reported_runs_give_the_same_path_with_one_compiled_chunk(traces, capsys):
    calls = []
    reported = sj.compress(_column(), 0.2, unload=True, progress=lambda *a: calls.append(a))
    assert traces.count("_chunk") == 1, traces  # chunks of 1, 4, 16, ... steps: one program (a traced count)
    first = len(traces)
    plain = sj.compress(_column(), 0.2, unload=True)  # one chunk of max_steps
    shown = sj.compress(_column(), 0.2, unload=True, progress=True)
    assert len(traces) == first, traces[first:]
    for result in (plain, shown):
        np.testing.assert_array_equal(result.displacement, reported.displacement)
        np.testing.assert_array_equal(result.force, reported.force)
        np.testing.assert_array_equal(result.iterations, reported.iterations)
    assert [c[0] for c in calls if c[3]] == ["settle", "loading", "unloading"]  # each phase's end reported
    assert calls[0][2] == 1  # the first chunk (it compiles) is one step
    err = capsys.readouterr().err  # not a terminal: no carriage returns, a few whole lines
    lines = err.splitlines()
    assert "\r" not in err, lines
    ends = [line for line in lines if not line.startswith("compiling … ")]  # each phase's end (+ one per 10 s)
    assert list(dict.fromkeys(line.split()[0] for line in ends)) == ["settle", "loading", "unloading"], lines
    assert all(" µm  F = " in line and " pN  steps " in line for line in ends), ends
    loading = [line for line in ends if line.split()[0] == "loading"][-1]
    assert f"steps {int((reported.phase == 1).sum()):5d}" in loading


def test_checkpoints_stay_every_n_steps_with_progress(tmp_path, monkeypatch):
    import socbjax._protocol as protocol

    saved, save = [], protocol._Run._save

    def spy(run, index, state):
        saved.append((index, int(state.steps)))
        save(run, index, state)

    monkeypatch.setattr(protocol._Run, "_save", spy)
    checkpoint = sj.Checkpoint(tmp_path / "run.ckpt.h5", every=4)
    result = sj.compress(_column(), 0.2, unload=True, checkpoint=checkpoint, progress=lambda *a: None)
    steps = [int(result.iterations[0])] + [int((result.phase == k).sum()) for k in (1, 2)]  # settle's: row 0
    assert saved and saved == [(i, s) for i, n in enumerate(steps) for s in range(4, n, 4)]  # chunks end at checkpoints


def test_terminal_line_is_rewritten_in_place_and_ticks_while_compiling():
    out = _Terminal()
    bar = Progress(True, 0.3, stream=out)
    bar.start()
    deadline = time.monotonic() + 60
    while "compiling … 1 s" not in out.getvalue() and time.monotonic() < deadline:
        time.sleep(0.05)  # the ticker thread refreshes the elapsed time about once a second
    bar("loading", 0.15, 12, 3.25)
    bar("loading", 0.3, 20, 4.5, done=True)
    bar.close()
    text = out.getvalue()
    assert "compiling … 1 s" in text
    assert "\r  loading [###############               ] u =  0.1500 µm  F =      3.25 pN  steps    12" in text
    assert text.endswith("s\n") and text.count("\n") == 1  # one finished line; the rest rewritten in place


def test_log_lines_are_sparse_and_callbacks_unchanged():
    out = io.StringIO()
    bar = Progress(True, 1.0, stream=out)
    for steps in range(1, 200):  # many quick chunks: only the first line and the phase's end are written
        bar("loading", steps / 200, steps, 1.0, done=steps == 199)
    bar.close()
    assert len(out.getvalue().splitlines()) == 2
    seen = []
    Progress(lambda *a: seen.append(a), 1.0)("settle", 0.0, 3, 0.5, True)
    assert seen == [("settle", 0.0, 3, True)]  # the public hook: progress(phase, u, steps, done)

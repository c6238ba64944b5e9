"""The learned-model file: checked loads, rejected files moved aside (never overwritten), one owner
per file, no debris from killed saves, and a SIGTERM'd node that saves."""
import json
import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from gyro_thermal_comp.nodes import state_store
from gyro_thermal_comp.nodes.state_store import FORMAT, StateFileInUse, StateStore, StateStoreError

TERMS = ['temperature', 'temperature_rate', 'constant']


def good_state(n=3):
    return {'terms': TERMS[:n], 'temperature_ref_c': 25.0, 'x': [1e-5, -2e-6, 3e-4][:n],
            'P': [[1e-8 if i == j else 0.0 for j in range(n)] for i in range(n)]}


def record(**changes):
    rec = {'format': FORMAT, 'saved_unix_s': 1000.0, **good_state()}
    rec.update(changes)
    return json.dumps(rec)


def plausible(state):
    """What the node's validator does beyond the store's own checks: terms and magnitudes."""
    if state['terms'] != TERMS:
        raise ValueError(f'terms {state["terms"]} are not {TERMS}')
    if max(abs(v) for v in state['x']) > 1.0:
        raise ValueError('implausible parameter magnitude')


@pytest.fixture
def store(tmp_path):
    s = StateStore(tmp_path / 's.json')
    yield s
    s.release()


def test_round_trip(store):
    store.acquire()
    store.save(good_state())
    result = store.load(plausible)
    assert result.warm and result.moved_to is None
    assert result.status == f'warm start from {store.path}'
    assert result.state == good_state()


def test_missing_file_is_a_cold_start_and_moves_nothing(store):
    result = store.load(plausible)
    assert result.state is None and result.moved_to is None
    assert result.status == f'cold start: no state file at {store.path}'
    assert sorted(p.name for p in store.path.parent.iterdir()) == ['s.json.lock']


BAD_FILES = {
    'huge x (the node validator)': (record(x=[1e300, 0.0, 0.0]), 'implausible parameter magnitude'),
    'other terms (the node validator)': (record(terms=['a', 'b', 'c']), 'does not fit this model'),
    'bool in x': (record(x=[True, 0.0, 0.0]), 'x[0] = True'),
    'string in x': (record(x=['1', 0.0, 0.0]), "x[0] = '1'"),
    'empty x': (record(x=[]), 'no parameter list x'),
    'NaN literal': (record().replace('1e-05', 'NaN'), 'non-finite number NaN'),
    'Infinity literal': (record().replace('1e-05', '-Infinity'), 'non-finite number -Infinity'),
    'huge integer': (record().replace('1e-05', '1' + '0' * 400), 'x[0]'),
    'newer format': (record(format='gyro_thermal_comp/stkf_state/2'), "format 'gyro_thermal_comp/stkf_state/2'"),
    'no format': (json.dumps(good_state()), 'format None'),
    'terms not strings': (record(terms=[1, 2, 3]), 'terms [1, 2, 3]'),
    'terms of other length': (record(terms=TERMS[:2]), 'not 3 names'),
    'P not square': (record(P=[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), 'covariance P: not 3 x 3'),
    'P asymmetric': (record(P=[[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]), 'not symmetric'),
    'P negative variance': (record(P=[[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]), 'negative variance'),
    'P with a bool': (record(P=[[True, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]), 'non-numeric entry'),
    'not JSON': ('{not json', 'not valid JSON'),
    'JSON list': ('[1, 2]', 'not a JSON object'),
    'empty file': ('', 'is empty'),
}


@pytest.mark.parametrize('content, reason', BAD_FILES.values(), ids=BAD_FILES.keys())
def test_bad_file_is_a_cold_start_and_moved_aside_intact(store, content, reason):
    store.path.write_text(content)
    result = store.load(plausible)
    assert result.state is None
    assert result.status.startswith(f'cold start: state file {store.path} ')
    assert reason in result.status
    assert result.status.endswith(f'; moved aside to {result.moved_to}')
    assert result.moved_to.parent == store.path.parent
    assert result.moved_to.name.startswith('s.json.rejected-') and result.moved_to.name.endswith('Z')
    assert result.moved_to.read_text() == content
    assert not store.path.exists()
    store.save(good_state())   # the cold-started node may save again: the rejected file is untouched
    assert result.moved_to.read_text() == content


def test_rejected_files_never_overwrite_each_other(store, monkeypatch):
    fixed = time.gmtime(1_700_000_000)
    monkeypatch.setattr(state_store.time, 'gmtime', lambda *a: fixed)   # all in the same second
    moved = []
    for i in range(3):
        store.path.write_text(f'bad {i}')
        moved.append(store.load(plausible).moved_to)
    assert [p.name for p in moved] == ['s.json.rejected-20231114T221320Z', 's.json.rejected-20231114T221320Z-1',
                                       's.json.rejected-20231114T221320Z-2']
    assert [p.read_text() for p in moved] == ['bad 0', 'bad 1', 'bad 2']


def test_a_rejected_file_that_cannot_be_moved_is_not_saved_over(store, monkeypatch):
    store.path.write_text('{not json')

    def refuse(src, dst):
        raise PermissionError(13, 'Permission denied')

    monkeypatch.setattr(state_store.os, 'rename', refuse)
    result = store.load(plausible)
    assert result.state is None and result.moved_to is None
    assert 'not valid JSON' in result.status and 'could not move it aside' in result.status
    with pytest.raises(StateStoreError, match='could not be moved aside'):
        store.save(good_state())
    assert store.path.read_text() == '{not json'


def test_save_refuses_a_state_that_would_not_load_back(store):
    store.acquire()
    store.save(good_state())
    before = store.path.read_text()
    with pytest.raises(StateStoreError, match=r'x\[1\]'):
        store.save({**good_state(), 'x': [0.0, float('nan'), 0.0]})
    assert store.path.read_text() == before


def test_second_store_is_refused_until_the_first_releases(store):
    store.acquire()
    other = StateStore(store.path)
    with pytest.raises(StateFileInUse, match=f'in use by another node .*pid {os.getpid()}'):
        other.acquire()
    with pytest.raises(StateFileInUse):
        other.load(plausible)
    with pytest.raises(StateStoreError, match='does not hold'):
        other.save(good_state())
    store.release()
    other.acquire()
    other.save(good_state())
    with pytest.raises(StateFileInUse):
        store.acquire()
    other.release()


HOLDER = '''
import sys
from gyro_thermal_comp.nodes.state_store import StateStore
s = StateStore(sys.argv[1]); s.acquire(); print('locked', flush=True); sys.stdin.read()
'''


def test_lock_is_refused_across_processes_and_freed_by_death(store):
    holder = subprocess.Popen([sys.executable, '-c', HOLDER, str(store.path)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == 'locked'
        with pytest.raises(StateFileInUse, match=f'pid {holder.pid}'):
            store.acquire()
    finally:
        holder.kill()   # SIGKILL: no release() runs; the kernel drops the flock with the process
        holder.wait(timeout=10)
    store.acquire()
    assert store.held


def test_orphaned_temp_files_are_removed_on_acquire_and_nothing_else(store):
    folder = store.path.parent
    orphans = ['.s.json.tmp-ab12_x9z', '.s.json.k3j5h2g1']   # this module's prefix, and the earlier one
    keep = ['.s.json.bak', '.s.json.tmp-ab12_x9z.keep', '.s.json.tmp-abc', '.other.json.tmp-ab12_x9z',
            's.json.rejected-20240101T000000Z', 'notes.txt', '.s.json.Backup01']
    for name in orphans + keep:
        (folder / name).write_text('x')
    (folder / '.s.json.tmp-dir12345').mkdir()
    store.acquire()
    assert sorted(p.name for p in folder.iterdir()) == sorted(keep + ['.s.json.tmp-dir12345', 's.json.lock'])


def test_interrupted_save_leaves_the_last_good_file_and_no_temp(store, monkeypatch):
    store.acquire()
    store.save(good_state())
    before = store.path.read_text()

    def half_then_signal(obj, f, **kw):
        f.write(json.dumps(obj)[:40])
        raise KeyboardInterrupt   # what SIGINT/SIGTERM raise in the middle of a write

    monkeypatch.setattr(state_store.json, 'dump', half_then_signal)
    with pytest.raises(KeyboardInterrupt):
        store.save({**good_state(), 'x': [9e-5, 9e-5, 9e-5]})
    assert store.path.read_text() == before
    assert sorted(p.name for p in store.path.parent.iterdir()) == ['s.json', 's.json.lock']


KILLED_SAVER = '''
import json, os, signal, sys
from gyro_thermal_comp.nodes import state_store
def half_then_die(obj, f, **kw):
    f.write(json.dumps(obj)[:40]); f.flush()
    os.kill(os.getpid(), signal.SIGKILL)   # power cut / OOM killer in the middle of a save
state_store.json.dump = half_then_die
s = state_store.StateStore(sys.argv[1]); s.acquire()
s.save({'terms': ['a'], 'temperature_ref_c': 25.0, 'x': [1.0]})
'''


def test_killed_save_keeps_the_main_file_and_the_next_owner_cleans_up(store):
    store.acquire()
    store.save(good_state())
    store.release()
    proc = subprocess.run([sys.executable, '-c', KILLED_SAVER, str(store.path)], timeout=60)
    assert proc.returncode == -signal.SIGKILL
    names = [p.name for p in store.path.parent.iterdir()]
    assert any(n.startswith('.s.json.tmp-') for n in names), names   # the debris a killed save leaves
    result = store.load(plausible)
    assert result.state == good_state()
    assert sorted(p.name for p in store.path.parent.iterdir()) == ['s.json', 's.json.lock']


# ---------------------------------------------------------------- live: the real node process
def test_live_node_saves_its_state_on_sigterm(tmp_path):
    """systemd / docker stop send SIGTERM: the node must save like on Ctrl-C and exit 0."""
    from gyro_thermal_comp.thermal.estimator import ThermalDriftEstimator
    model = ThermalDriftEstimator().model
    n = len(model.names)
    path = tmp_path / 's.json'
    x = [1e-6 * (i + 1) for i in range(n)]
    path.write_text(json.dumps({'format': FORMAT, 'saved_unix_s': 1000.0, 'terms': list(model.names),
                                'temperature_ref_c': model.temperature_ref_c, 'x': x,
                                'P': [[1e-8 if i == j else 0.0 for j in range(n)] for i in range(n)]}))
    proc = subprocess.Popen([sys.executable, '-m', 'gyro_thermal_comp.nodes.stkf_node', '--ros-args',
                             '-p', f'state_file:={path}'], stderr=subprocess.PIPE, text=True)
    log: list[str] = []
    reader = threading.Thread(target=lambda: log.extend(iter(proc.stderr.readline, '')), daemon=True)
    reader.start()
    try:
        wait_for(lambda: any('warm start from' in line for line in log), 60, 'the warm start log line', proc, log)
        # The handler is installed just before spinning: SIGTERM earlier would just kill the process.
        wait_for(lambda: sigterm_caught(proc.pid), 30, 'a SIGTERM handler', proc, log)
        proc.send_signal(signal.SIGTERM)
        rc = proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
    reader.join(timeout=10)
    assert rc == 0, ''.join(log)
    saved = json.loads(path.read_text())
    assert saved['saved_unix_s'] > 1000.0, ''.join(log)
    assert saved['x'] == x and saved['terms'] == list(model.names)
    assert any('stopped:' in line for line in log), ''.join(log)


def wait_for(condition, timeout_s, what, proc, log):
    end = time.monotonic() + timeout_s
    while not condition():
        if proc.poll() is not None or time.monotonic() > end:
            pytest.fail(f'waited {timeout_s} s for {what} (node exit code {proc.poll()}); node log:\n' + ''.join(log))
        time.sleep(0.05)


def sigterm_caught(pid) -> bool:
    """True once the process has a handler for SIGTERM (Linux: the SigCgt mask in /proc)."""
    for line in open(f'/proc/{pid}/status'):
        if line.startswith('SigCgt:'):
            return bool(int(line.split()[1], 16) >> (signal.SIGTERM - 1) & 1)
    return False

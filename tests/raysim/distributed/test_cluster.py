"""A local Dask cluster's workers ignore SIGINT, the first ones and those a nanny restarts."""

from __future__ import annotations

import json
import subprocess
import sys

from tests.cli import cli_env

# a fresh interpreter: the fork server is per process, and one started earlier by another test
# would be used as it is
_KILL_A_WORKER = '''
import json, os, signal, time

from raysim.distributed.cluster import connect


def sigint_ignored(pid):
    for line in open(f"/proc/{pid}/status"):
        if line.startswith("SigIgn:"):
            return bool(int(line.split()[1], 16) >> (signal.SIGINT - 1) & 1)


def worker_pid(client):
    return next(iter(client.run(os.getpid).values()))


def main():
    with connect(workers=1) as cluster:
        first = worker_pid(cluster.client)
        ignored = [sigint_ignored(first)]
        os.kill(first, signal.SIGKILL)
        deadline = time.monotonic() + 60
        while True:  # the nanny starts a new worker process
            try:
                pid = worker_pid(cluster.client)
            except Exception:
                pid = first
            if pid != first:
                break
            assert time.monotonic() < deadline, "no worker restarted"
            time.sleep(0.1)
        ignored.append(sigint_ignored(pid))
    print(json.dumps(ignored))


if __name__ == "__main__":  # worker processes import this file again
    main()
'''


def test_a_worker_the_nanny_restarts_ignores_sigint_like_the_first(tmp_path):
    """The first workers came from a fork server that ignores SIGINT; a worker killed mid-run
    was restarted by Dask's default start method and took the next Ctrl-C to the process group
    (tracebacks) instead of leaving it to the client."""
    (tmp_path / "kill.py").write_text(_KILL_A_WORKER)
    done = subprocess.run([sys.executable, "kill.py"], cwd=tmp_path, env=cli_env(),
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    first, restarted = json.loads(done.stdout.splitlines()[-1])
    assert first, "the first worker takes SIGINT"
    assert restarted, "the restarted worker takes SIGINT"

"""Jobs larger than the memory the machine leaves (here an address-space limit, as `ulimit -v`
in a batch job) raise MemoryError with the library's message instead of aborting the
interpreter. Each runs in a child interpreter under the limit."""

import os
import subprocess
import sys
import textwrap

from conftest import SCENE

# About 3.8 GiB, as `ulimit -v 4000000`.
LIMIT = 4_000_000 * 1024


def _limited(code):
    def preexec():
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (LIMIT, LIMIT))

    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        preexec_fn=preexec,
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )


def _names_a_limit(text):
    # `ulimit -v`, or on a machine with less than that free the tighter limit.
    return any(k in text for k in ("ulimit -v", "MemAvailable", "cgroup"))


def test_a_film_over_the_address_space_raises_memory_error():
    r = _limited(
        f"""
        import striae
        try:
            striae.render({SCENE!r}, res=(32768, 32768), spp=1, threads=1)
        except MemoryError as e:
            print("MemoryError:", e)
        """
    )
    assert r.returncode == 0, r.stderr
    assert "MemoryError: res=(32768, 32768)" in r.stdout, r.stdout
    assert "GiB" in r.stdout and _names_a_limit(r.stdout), r.stdout


def test_masks_over_the_address_space_raise_memory_error():
    r = _limited(
        """
        import striae
        try:
            striae.layers(setting=1, layers=8, res=16384).masks
        except MemoryError as e:
            print("MemoryError:", e)
        """
    )
    assert r.returncode == 0, r.stderr
    assert "MemoryError: res=16384 (8 layers)" in r.stdout, r.stdout
    assert _names_a_limit(r.stdout), r.stdout

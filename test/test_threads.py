"""The BLAS thread limit of the package's processes (:mod:`mech_balance.threads`)."""

import os
import subprocess
import sys

from mech_balance import threads
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_the_default_is_one_thread_and_the_users_choice_is_respected():
    assert threads.blas_threads({}) == threads.DEFAULT_THREADS == 1
    assert threads.blas_threads({'MECH_BALANCE_BLAS_THREADS': '3'}) == 3
    for var in threads.USER_VARS:
        assert threads.blas_threads({var: '4'}) is None          # left as the user set it
        assert threads.blas_threads({var: '4', threads.ENV: '2'}) == 2


@pytest.mark.parametrize('text', ['0', '-1', 'two', '', '1.5'])
def test_a_bad_count_is_refused_naming_the_variable(text):
    with pytest.raises(ValueError, match=rf"MECH_BALANCE_BLAS_THREADS: got '{text}'"):
        threads.blas_threads({threads.ENV: text})


def _pool_in_child(env_extra, code):
    env = {k: v for k, v in os.environ.items()
           if k not in threads.USER_VARS and k != threads.ENV}
    env.update(env_extra, PYTHONPATH=ROOT)
    out = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True,
                         text=True, timeout=120)
    return out


LIMIT_AND_READ = (
    'from mech_balance import threads; import threadpoolctl; n = threads.limit_blas_threads();'
    ' print(n, [p["num_threads"] for p in threadpoolctl.threadpool_info()'
    ' if p["user_api"] == "blas"])')


def test_the_limit_reaches_numpys_blas():
    pytest.importorskip('threadpoolctl')
    out = _pool_in_child({}, LIMIT_AND_READ)
    assert out.returncode == 0, out.stderr
    n, pools = out.stdout.split(' ', 1)
    assert n == '1' and pools.strip() != '[]' and set(eval(pools)) == {1}
    out = _pool_in_child({threads.ENV: '2'}, LIMIT_AND_READ)
    assert out.stdout.startswith('2 ') and set(eval(out.stdout.split(' ', 1)[1])) == {2}


def test_the_cli_refuses_a_bad_count_with_status_2():
    out = _pool_in_child({threads.ENV: 'many'},
                         'import sys; from mech_balance.cli.main import main; '
                         'sys.exit(main(["scenes"]))')
    assert out.returncode == 2
    assert "MECH_BALANCE_BLAS_THREADS: got 'many'" in out.stderr


def test_release_memory_returns_freed_heap_to_the_system():
    code = ('import numpy as np; from mech_balance import threads\n'
            'def rss():\n'
            '    return next(int(l.split()[1]) for l in open("/proc/self/status")'
            ' if l.startswith("VmRSS"))\n'
            'base = rss()\n'
            'blocks = [np.ones(8192) for _ in range(20000)]\n'   # 1.3 GB in 64 kB blocks
            'keep = np.ones(8192)\n'        # above them: free() alone cannot shrink the heap
            'grown = rss()\n'
            'blocks.clear()\n'
            'kept = rss()\n'
            'ok = threads.release_memory()\n'
            'print(ok, grown - base, kept - base, rss() - base)')
    out = _pool_in_child({}, code)
    assert out.returncode == 0, out.stderr
    ok, grown, kept, after = out.stdout.split()
    assert int(grown) > 500_000 and int(kept) > 0.9 * int(grown)   # freed, yet resident
    assert ok == 'True' and int(after) < 0.1 * int(grown)


def test_the_node_fixes_the_mmap_threshold_so_big_temporaries_return_at_free():
    code = ('import sys; import numpy as np; from mech_balance import threads\n'
            'def rss():\n'
            '    return next(int(l.split()[1]) for l in open("/proc/self/status")'
            ' if l.startswith("VmRSS"))\n'
            'ok = threads.return_large_blocks() if sys.argv[1] == "fix" else None\n'
            'np.ones(2 ** 20)\n'                # 8 MB, freed: glibc would raise its threshold
            'base = rss()\n'
            'arrays = [np.ones(2 ** 17) for _ in range(20)]\n'    # 20 MB of 1 MB temporaries
            'keep = np.ones(16)\n'
            'del arrays\n'
            'print(ok, rss() - base)')

    def run(arg, env=None):
        out = subprocess.run([sys.executable, '-c', code, arg], capture_output=True, text=True,
                             timeout=120, env=dict(os.environ, PYTHONPATH=ROOT, **(env or {})))
        assert out.returncode == 0, out.stderr
        ok, grown = out.stdout.split()
        return ok, int(grown)

    assert run('dynamic')[1] > 2048                  # kB kept with glibc's dynamic threshold
    ok, grown = run('fix')
    assert ok == 'True' and grown < 1024             # returned at free
    assert run('fix', {'MALLOC_MMAP_THRESHOLD_': '65536'})[0] == 'False'   # the user's own

"""The driver of the tests that kill a job after each of its renames (tests/test_output_sets.py,
tests/test_calibration_gcp.py): ``python -c KILL_DRIVER OUT1,OUT2,... COMMAND ARGS...`` runs the command once per
output folder in a forked child that SIGKILLs itself right after its k-th rename (``os.replace``, ``os.rename``,
``io.atomic._exchange``), prints ``STATUS k <wait status>`` per run, and stops after the first run that was not
killed (it got past its last rename); an exception in a run is printed as ``ERROR k ...`` on stderr."""

KILL_DRIVER = """
import os, signal, sys
import footprint_uq.io.atomic as A
from footprint_uq.cli.main import main
main.get_command(None, sys.argv[2])  # the command's modules imported once, before the forks
outs, args = sys.argv[1].split(","), sys.argv[2:]
for k, out in enumerate(outs, start=1):  # one forked run per kill point: killed after its k-th rename
    pid = os.fork()
    if pid == 0:
        n = [0]
        def hook(f):
            def w(*a, **kw):
                r = f(*a, **kw)
                n[0] += 1
                if n[0] == k:
                    os.kill(os.getpid(), signal.SIGKILL)
                return r
            return w
        os.replace, os.rename, A._exchange = hook(os.replace), hook(os.rename), hook(A._exchange)
        try:
            main(args + ["--out", out], standalone_mode=False)
        except BaseException as e:
            print("ERROR", k, type(e).__name__, e, file=sys.stderr, flush=True)
            os._exit(1)
        os._exit(0)
    status = os.waitpid(pid, 0)[1]
    print("STATUS", k, status, flush=True)
    if status != signal.SIGKILL:  # past the last rename: the rest would not be killed either
        break
"""

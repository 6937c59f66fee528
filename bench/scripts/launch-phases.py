"""Times the phases of `nerve launch` of a ticker and 49 relays in a chain
(the file `nerve bench control` launches) from its stderr lines, three
launches, each brought down after. BENCHMARKS.md section 3, 2026-11-27.

    python3 bench/scripts/launch-phases.py [NERVE_BIN_DIR]   # default target/release
"""
import os, shutil, subprocess, sys, tempfile, time

bin_dir = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else "target/release")
home = tempfile.mkdtemp(prefix="nerve-launch-phases-")
launch = os.path.join(home, "launch.toml")
text = 'robot = "ltx"\n\n[[agent]]\nname = "t1"\nkind = "ticker"\nperiod = "100ms"\n'
for i in range(1, 50):
    text += f'\n[[agent]]\nname = "r{i}"\nkind = "relay"\n'
for i in range(1, 50):
    src = "t1/tick" if i == 1 else f"r{i - 1}/out"
    text += f'\n[[connect]]\nfrom = "{src}"\nto = "r{i}/in"\n'
with open(launch, "w") as f:
    f.write(text)
env = dict(os.environ, NERVE_HOME=home, PATH=bin_dir + ":" + os.environ["PATH"])
for _ in range(3):
    t0 = time.perf_counter()
    p = subprocess.Popen(["nerve", "--robot", "ltx", "launch", launch], stderr=subprocess.PIPE, env=env, text=True)
    marks = {}
    for line in p.stderr:
        t = (time.perf_counter() - t0) * 1e3
        if "[1/50]" in line:
            marks["first started"] = t
        if "[50/50]" in line:
            marks["all started"] = t
        if "connected t1/tick" in line:
            marks["first connect"] = t
        if "connected r48/out" in line:
            marks["last connect"] = t
    p.wait()
    marks["end"] = (time.perf_counter() - t0) * 1e3
    print({k: round(v) for k, v in marks.items()})
    subprocess.run(["nerve", "--robot", "ltx", "down"], env=env, capture_output=True)
shutil.rmtree(home, ignore_errors=True)

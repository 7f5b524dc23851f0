#!/usr/bin/python3
"""Non-GUI LinuxCNC 'display' for timing runs.

Started by the `linuxcnc` launcher as  run_display.py -ini INIFILE.
Environment:
  LCNC_PROGRAM  absolute path of the G-code program to run (required)
  LCNC_OUT      output prefix (default /tmp/lcnc_run); writes PREFIX.samples (halsampler -t
                output: sample-number X Y Z, commanded joint positions each servo period)
                and PREFIX.status.json (errors, messages, outcome)
  LCNC_TIMEOUT  seconds to wait for the program to finish (default 900)
"""
import json, os, subprocess, sys, time
import linuxcnc

prog = os.environ["LCNC_PROGRAM"]
out = os.environ.get("LCNC_OUT", "/tmp/lcnc_run")
timeout = float(os.environ.get("LCNC_TIMEOUT", "900"))
status = {"program": prog, "errors": [], "messages": [], "outcome": "unknown"}

def log(*a):
    print("[run_display]", *a, file=sys.stderr, flush=True)

s = linuxcnc.stat()
c = linuxcnc.command()
e = linuxcnc.error_channel()

def drain_errors():
    while True:
        err = e.poll()
        if not err:
            return
        kind, text = err
        if kind in (linuxcnc.NML_ERROR, linuxcnc.OPERATOR_ERROR):
            status["errors"].append(text)
            log("ERROR:", text)
        else:
            status["messages"].append(text)
            log("msg:", text)

def wait_for(pred, what, tmo=10.0):
    t0 = time.time()
    while time.time() - t0 < tmo:
        s.poll()
        if pred():
            return True
        time.sleep(0.01)
    raise RuntimeError("timeout waiting for " + what)

def halcmd(*args):
    subprocess.run(["halcmd"] + list(args), check=True)

sampler = None
try:
    # wait for task to answer
    for _ in range(500):
        try:
            s.poll()
            break
        except linuxcnc.error:
            time.sleep(0.02)
    c.state(linuxcnc.STATE_ESTOP_RESET); c.wait_complete()
    c.state(linuxcnc.STATE_ON); c.wait_complete()
    wait_for(lambda: s.task_state == linuxcnc.STATE_ON, "machine on")
    c.mode(linuxcnc.MODE_MANUAL); c.wait_complete()
    c.home(-1); c.wait_complete()
    wait_for(lambda: all(s.homed[j] for j in range(s.joints)), "homing")
    c.mode(linuxcnc.MODE_AUTO); c.wait_complete()
    wait_for(lambda: s.task_mode == linuxcnc.MODE_AUTO, "auto mode")
    c.program_open(prog); c.wait_complete()
    drain_errors()

    fout = open(out + ".samples", "w")
    sampler = subprocess.Popen(["halsampler", "-t"], stdout=fout)
    time.sleep(0.2)
    halcmd("setp", "sampler.0.enable", "1")
    time.sleep(0.05)

    t_start = time.time()
    c.auto(linuxcnc.AUTO_RUN, 0)
    # wait until the interpreter leaves IDLE, then until it is idle again
    started = False
    while time.time() - t_start < timeout:
        time.sleep(0.005)
        s.poll()
        drain_errors()
        if s.interp_state != linuxcnc.INTERP_IDLE:
            started = True
        elif started or time.time() - t_start > 2.0:
            break
    else:
        status["outcome"] = "timeout"
    s.poll()
    status["wall_s"] = time.time() - t_start
    if status["outcome"] == "unknown":
        status["outcome"] = "done" if not status["errors"] else "error"
    status["final_pos"] = list(s.actual_position[:3])
    time.sleep(0.3)  # a few hundred idle samples after the end
    halcmd("setp", "sampler.0.enable", "0")
    status["sampler_overruns"] = subprocess.run(
        ["halcmd", "getp", "sampler.0.overruns"], capture_output=True, text=True).stdout.strip()
    time.sleep(0.5)  # let halsampler drain the FIFO
    drain_errors()
except Exception as ex:  # record and fall through to shutdown
    status["outcome"] = "exception"
    status["errors"].append(repr(ex))
    log("exception", repr(ex))
finally:
    if sampler is not None:
        sampler.terminate()
        sampler.wait()
    try:
        c.state(linuxcnc.STATE_OFF)
    except Exception:
        pass
    with open(out + ".status.json", "w") as f:
        json.dump(status, f, indent=1)
    log("outcome", status["outcome"])

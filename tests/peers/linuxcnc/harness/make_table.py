#!/usr/bin/python3
"""OUT/results/results.json (run_all.py) -> OUT/results/results.md, a markdown table, also
printed. Ratio = cnc / LinuxCNC; "SLOWER" marks cnc slower than LinuxCNC by more than 0.5 %.
"max dev." is the largest distance of LinuxCNC's commanded path from the programmed G0/G1
polyline (deviation.py; n/a for programs with arcs or NURBS).

Usage: make_table.py [--out DIR]   (DIR defaults to $LCNC_OUT_DIR or harness/out)"""
import argparse, json, os, subprocess, sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.environ.get("LCNC_OUT_DIR") or str(HERE / "out"))
    out = Path(ap.parse_args().out).resolve()
    R = json.loads((out / "results" / "results.json").read_text())
    lines = ["| program | LinuxCNC time (s) | cnc time (s) | cnc/LinuxCNC | LinuxCNC path (mm) | "
             "cnc path (mm) | LinuxCNC max dev. from programmed polyline (mm) | notes |",
             "|---|---|---|---|---|---|---|---|"]
    for k, v in R.items():
        lc = v["linuxcnc"]
        t = lc.get("time_s")
        c = v["cnc_time_s"]
        notes = []
        if lc.get("outcome") != "done":
            notes.append(f"LinuxCNC outcome: {lc.get('outcome')}")
        if lc.get("errors"):
            notes.append("LinuxCNC error: " + "; ".join(e.strip() for e in lc["errors"])[:200])
        if lc.get("gaps"):
            notes.append(f"{lc['gaps']} sample gaps")
        if c is None:
            notes.append("cnc refused: " + v["cnc_output"].replace("\n", " ")[:200])
        ratio = f"{c / t:.3f}" if (c is not None and t) else "-"
        if c is not None and t and lc.get("outcome") == "done" and c > t * 1.005:
            ratio = f"**{ratio} SLOWER**"
        dev = "-"
        smp = v.get("samples") or str(out / "runs" / (k + ".samples"))
        if os.path.exists(smp) and lc.get("outcome") == "done":
            r = subprocess.run([sys.executable, str(HERE / "deviation.py"), v["program_path"], smp],
                               capture_output=True, text=True)
            if r.returncode == 0 and r.stdout.strip():
                d = json.loads(r.stdout).get("max_dev_mm")
                dev = f"{d:.4f}" if d is not None else "n/a (arcs)"
        lines.append(f"| {v['program']} | {t if t is not None else '-'} | "
                     f"{c if c is not None else '-'} | {ratio} | {lc.get('path_mm', '-')} | "
                     f"{v.get('cnc_path_mm') or '-'} | {dev} | {' '.join(notes)} |")
    md = out / "results" / "results.md"
    md.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    print("written:", md, file=sys.stderr)


if __name__ == "__main__":
    main()

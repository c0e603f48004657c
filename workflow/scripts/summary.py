"""Every session's validation on one line of a TSV: the held-out slot's relative RMSE and PSNR
under the lighting measured at that slot and under lighting predicted from the other slots, and
the session's status: ok, failed (the jobs of it that failed, each of which leaves
OUT/logs/NAME/RULE.log.failed beside its log), or broken (its session.json or workflow.toml
could not be read, with the reason).

Run by the summary rule (Snakemake's script directive) when every job succeeded, and by the
workflow's onerror handler otherwise (snakemake --keep-going: the sessions that worked are
summarised with the others marked)."""

import json
import os

LIGHTINGS = ("measured", "predicted")


def failure(root, name):
    """The failed jobs of the session ("solve, report"), each leaving OUT/logs/NAME/RULE.log.failed
    beside its log (removed when the job runs again); "" when none."""
    logs = os.path.join(root, "logs", name)
    if not os.path.isdir(logs):
        return ""
    return ", ".join(sorted(f[: -len(".log.failed")] for f in os.listdir(logs)
                            if f.endswith(".log.failed")))


def write_summary(out, root, names, broken):
    header = ["session", "slot", "held_out", "photos", "pixels"]
    for lighting in LIGHTINGS:
        header += [f"{lighting}_rel_rmse", f"{lighting}_psnr_db"]
    header.append("status")
    rows = {}
    for name in names:
        failed = failure(root, name)
        path = os.path.join(root, name, "validate.json")
        if failed or not os.path.isfile(path):
            log = os.path.join(root, "logs", name)
            rows[name] = [name] + [""] * 4 + ["nan"] * 4 + [
                f"failed: {failed or 'not run'} (see {log}/)"
            ]
            continue
        with open(path) as f:
            v = json.load(f)
        row = [name, v["slot"], str(v["held_out"]).lower(), len(v["photos"]),
               v["measured"]["pixels"]]
        for lighting in LIGHTINGS:
            figures = v.get(lighting, {})  # none with rouen validate --no-predicted
            row += [figures.get("rel_rmse", "nan"), figures.get("psnr_db", "nan")]
        rows[name] = row + ["ok"]
    for name, reason in broken.items():
        rows[name] = [name] + [""] * 4 + ["nan"] * 4 + ["broken: " + " ".join(reason.split())]
    lines = ["\t".join(header)] + ["\t".join(str(x) for x in rows[n]) for n in sorted(rows)]
    os.makedirs(os.path.dirname(out) or ".", exist_ok=True)
    tmp = out + ".tmp"
    with open(tmp, "w") as f:
        f.write("\n".join(lines) + "\n")
    os.replace(tmp, out)


if "snakemake" in globals():
    write_summary(snakemake.output[0], snakemake.params.root, snakemake.params.names,
                  snakemake.params.broken)

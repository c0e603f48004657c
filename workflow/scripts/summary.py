"""The summary rule (run by Snakemake's script directive): every session's validation on one
line of a TSV, the held-out slot's relative RMSE and PSNR under the lighting measured at that
slot and under lighting predicted from the other slots."""

import json

LIGHTINGS = ("measured", "predicted")

header = ["session", "slot", "held_out", "photos", "pixels"]
for lighting in LIGHTINGS:
    header += [f"{lighting}_rel_rmse", f"{lighting}_psnr_db"]
lines = ["\t".join(header)]
for name, path in zip(snakemake.params.names, snakemake.input):
    with open(path) as f:
        v = json.load(f)
    row = [name, v["slot"], str(v["held_out"]).lower(), len(v["photos"]), v["measured"]["pixels"]]
    for lighting in LIGHTINGS:
        figures = v.get(lighting, {})  # none with rouen validate --no-predicted
        row += [figures.get("rel_rmse", "nan"), figures.get("psnr_db", "nan")]
    lines.append("\t".join(str(x) for x in row))
with open(snakemake.output[0], "w") as f:
    f.write("\n".join(lines) + "\n")

"""docs/perception.md's hourglass refusal curve: one row per sensor and waist, from the JSONs that
`python -m suite bench lookalike --out DIR` writes (one per sensor, `suite.bench.lookalike`): the
hourglasses each pipeline refused, the robust pipeline's 95% interval, the cans and dented cans its
side check refused, and its recall."""

from __future__ import annotations


def refusal_table(docs: list[dict]) -> str:
    """docs/perception.md's refusal curve: one row per sensor and waist, from the sweep's JSONs."""
    lines = ["| sensor | waist / r | hourglasses | refused: paper (top) | refused: robust-top (top) "
             "| refused: robust (top, front, back), 95% interval | cans refused by the side check | dented cans refused by the side check "
             "| robust's recall: cans, dented |",
             "|---|---|---|---|---|---|---|---|---|"]
    for doc in docs:
        by = {(r["waist"], r["pipeline"]): r for r in doc["curve"]}
        preset, _, corr = doc["sensor"].partition("@")
        sensor = "perfect" if preset == "none" else preset + (f", noise correlated over {corr} px" if corr else "")
        for w in doc["waists"]:
            rob = by[(w, "robust")]

            def refused(pipeline, bold=False):
                r = by[(w, pipeline)]
                cell = f"{100 * r['refused']:.0f}% ({r['hourglasses_refused']})"
                if not bold:
                    return cell
                lo, hi = r["refused_ci95"]
                return f"**{cell}**, {100 * lo:.0f}-{100 * hi:.0f}%"
            cells = [sensor, f"{w:g}", str(rob["hourglasses"]), refused("paper"), refused("robust-top"),
                     refused("robust", bold=True), f"{rob['cans_refused_by_side_check']} of {rob['cans']}",
                     f"{rob['dented_refused_by_side_check']} of {rob['dented']}",
                     f"{rob['cans_found']}/{rob['cans']}, {rob['dented_found']}/{rob['dented']}"]
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"

# `snakemake --report results/report.html`: every table and figure output is wrapped in report() with a caption
# from tables.yaml (the thesis' table) and our verdict (results/tables/<id>.score.json when built), one
# category per stage. Captions are Jinja templates that Snakemake renders per output, written here when the
# workflow is parsed (redsup.report). Included right after common.smk: the stage rule files use these helpers.
import redsup.report as report_captions
import redsup.tables.registry as _table_registry

_REPORT_DIR = ".snakemake/report_captions"
_REGISTRY = _table_registry.load_registry()
TABLE_CAPTION = report_captions.write_caption_template(f"{_REPORT_DIR}/table.rst", "table", TABLE_IDS)
FIGURE_CAPTION = report_captions.write_caption_template(
    f"{_REPORT_DIR}/figure.rst", "figure", [f for f in FIGURE_IDS if f in _REGISTRY["tables"]])
OVERVIEW_CAPTION = report_captions.write_caption(
    f"{_REPORT_DIR}/world_frame_overview.rst",
    "One test frame of the embedded driving world: the cameras with the 2D detections the stages start from.")
SCORECARD_CAPTION = report_captions.write_caption(
    f"{_REPORT_DIR}/scorecard.rst",
    "Every table's claims in one view: reproduces / inconclusive / contradicted / not testable, and Kendall "
    "tau of our row order against the thesis'.")
RUN_TIME_CAPTION = report_captions.write_caption(
    f"{_REPORT_DIR}/run_time.rst",
    "Where this run's time went: wall time, CPU time and peak resident memory per rule and per stage, from "
    "every job's Snakemake benchmark file (results/benchmarks/).")


def _report_category(table_id):
    stage = _REGISTRY["tables"][table_id]["stage"] if table_id in _REGISTRY["tables"] else "data"
    return f"{stage}: {_REGISTRY['stages'][stage].split(':')[0]}" if ":" in _REGISTRY["stages"][stage] else stage


def report_table(path, ext):
    """A table output (wildcard ``table``) for the report."""
    return report(path, caption=TABLE_CAPTION, category=lambda wildcards: _report_category(wildcards.table),
                  subcategory="{table}", labels={"id": "{table}", "file": ext})


def report_figure(path):
    """A figure output (wildcard ``figure``, a figure id of tables.yaml) for the report."""
    return report(path, caption=FIGURE_CAPTION, category=lambda wildcards: _report_category(wildcards.figure),
                  subcategory="{figure}", labels={"id": "{figure}", "file": "png"})


def report_fixed(path, caption, name, ext):
    """An output without wildcards (overview figure, scorecard, run time) in the category "run summary"."""
    return report(path, caption=caption, category="run summary", subcategory=name, labels={"id": name, "file": ext})

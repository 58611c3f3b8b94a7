"""Paper-vs-ours tables: the registry of reproduced tables (data/tables.yaml), the thesis' numbers
(data/paper_values.csv), Kendall's tau and claim checks, and the table / scorecard writers."""
import importlib

# Loaded on first use (PEP 562): the stage plans import `redsup.tables.contract` in every job, and the writers'
# pandas costs about a second of start-up in jobs that never write a table.
_EXPORTS = {
    "claims": ("evaluate_check", "evaluate_claims", "evaluate_claims_on_paper", "headline_tau", "kendall_tau"),
    "registry": ("DATA_DIR", "PAPER_VALUES_CSV", "REGISTRY_YAML", "align", "as_frame", "column_key",
                 "load_registry", "paper_directions", "paper_table", "paper_values", "row_key", "table_ids",
                 "table_info"),
    "writer": ("build_table", "fmt_value", "tex_escape", "write_scorecard", "write_table"),
}
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}


def __getattr__(name: str):
    if name in _MODULE_OF:
        return getattr(importlib.import_module(f"redsup.tables.{_MODULE_OF[name]}"), name)
    raise AttributeError(f"module 'redsup.tables' has no attribute {name!r}")


__all__ = [
    "DATA_DIR", "PAPER_VALUES_CSV", "REGISTRY_YAML", "align", "as_frame", "build_table",
    "column_key", "evaluate_check", "evaluate_claims", "evaluate_claims_on_paper", "fmt_value", "headline_tau",
    "kendall_tau", "load_registry", "paper_directions", "paper_table", "paper_values", "row_key",
    "table_ids", "table_info", "tex_escape", "write_scorecard", "write_table", "mlflow_plan",
]


def mlflow_plan(registry: dict | None = None) -> dict:
    """The plan for ``redsup.tracking.init_store``: every stage of tables.yaml, one parent per table id,
    plus the ``world`` and ``data_preparation`` parents under stage ``data``."""
    from redsup.tables.registry import load_registry

    reg = registry or load_registry()
    parents = [
        {"name": "world", "stage": "data", "description": "Embedded driving world: generation and rendering"},
        {"name": "data_preparation", "stage": "data",
         "description": "Data preparation: crops, intrinsics, LiDAR depth maps, 2D detections"},
    ]
    parents += [{"name": t, "stage": e["stage"], "description": f"{e['title']}: {e['description']}"}
                for t, e in reg["tables"].items()]
    return {"stages": dict(reg["stages"]), "parents": parents}

"""corn_drake: CORN (ICLR 2024) rebuilt as a Drake systems-framework project."""

__version__ = "0.1.0"


def __getattr__(name: str):
    # MODELS_DIR and DIAGRAMS_DIR are resolved on first use by corn_drake.package_data (the
    # installed package's copy, or the source checkout's folders), so `import corn_drake` never
    # fails on a missing folder, and a missing one is named where it is needed.
    if name in ("MODELS_DIR", "DIAGRAMS_DIR"):
        from corn_drake import package_data

        return package_data.data_dir(name.removesuffix("_DIR").lower())
    raise AttributeError(f"module 'corn_drake' has no attribute {name!r}")

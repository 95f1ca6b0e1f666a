"""How a config is read, layered, overridden and checked (YAML files, --set, the bounds of
every field); the typed configs themselves are config/'s modules."""

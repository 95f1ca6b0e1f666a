"""The commands that show and ship results: stills and animations, shipped weights, tables
and curves over runs, merged planner reports."""

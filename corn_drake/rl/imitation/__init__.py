"""Learning the 6D chooser from the 6D expert's labels (`corn-drake label`, `corn-drake
fit-chooser`): the labelled states' candidate features (dataset.py) and the fit (fit.py). The
network it fits chooses at run time from rl/primitive/value_chooser/."""

"""The learned 6D chooser at run time: a value network over a primitive run's candidates, no
simulator. A run folder whose `chooser` is "expert_value" chooses this way; rl/imitation/ fits
the network to the 6D expert's labels."""

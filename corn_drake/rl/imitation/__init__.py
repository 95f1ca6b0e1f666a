"""The learned 6D chooser: a value network fitted to the 6D expert's labels (`corn-drake label`,
`corn-drake fit-chooser`), choosing among a primitive run's candidates with no simulator."""

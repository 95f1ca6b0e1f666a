"""The commands that make data: object libraries, contact data, outcome data and the 6D
expert's labels."""

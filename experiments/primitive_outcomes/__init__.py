"""Studies of the contact-primitive policy choosing by a model of its primitives' outcomes (README.md)."""

"""Studies of the contact-primitive policy's training (README.md)."""

"""The policies as LeafSystems closing the loop inside a diagram: the teacher, the recurrent
student, the contact-primitive policy."""

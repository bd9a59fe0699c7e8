"""The components floor: the component contract, the component models and effects the signatures
name, FMU components, and the signature library bound to its classes (``docs/components.md``)."""

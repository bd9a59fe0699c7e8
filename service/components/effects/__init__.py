"""The effect catalog's models: additions the diagnosis can splice into the base model.

Each effect is a :class:`service.components.component.SplicedEffect` (``value_in`` → ``value_out``) with a
signature in ``signatures/effects/`` saying where it applies. At every parameter's ``null`` value an
effect is the identity, so the base model is the effect's null hypothesis. The catalog's equations:
``docs/components.md``.
"""

"""Original (vendor) hands: specs, URDF loading, parsing into canonical params, the action map, fidelity.

Submodules: ``spec`` (HandSpec YAML), ``urdf`` (robust original-URDF loading), ``parse`` (original ->
params), ``action`` (original <-> canonical joint vectors), ``fidelity`` (canonical vs original errors).
"""

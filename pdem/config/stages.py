"""A staged scene as one stage runs it (a scene transform of the grammar floor)."""

from __future__ import annotations


def stage_scene(scene, k: int):
    """The scene as stage ``k`` runs it: joints changed by stages 0..k, and the solve settings
    (end condition, damping, mass scaling, the no-progress window) of stage ``k``."""
    joints = dict(scene.joints)
    for st in scene.stages[:k + 1]:
        for name, changes in st.joints.items():
            joints[name] = joints[name].model_copy(update=changes)
            type(joints[name]).model_validate(joints[name].model_dump())  # bounds checked
    st = scene.stages[k]
    update = {}
    if st.solve is not None:
        update = {key: getattr(st.solve, key) for key in ("time", "steps", "ratio", "max_steps")}
        if st.solve.damping is not None:
            update["damping"] = st.solve.damping
        if st.solve.mass_scaling is not None:
            update["mass_scaling"] = st.solve.mass_scaling
        if st.solve.no_progress_steps is not None:
            update["no_progress_steps"] = st.solve.no_progress_steps
    return scene.model_copy(update={"joints": joints,
                                    "solve": scene.solve.model_copy(update=update)})

from typing import TYPE_CHECKING

from piste import _lazy_exports

# every name is imported when first asked for (PEP 562; tests/test_lazy_imports.py)
__all__, __getattr__, __dir__ = _lazy_exports(__name__, {
    "course": ("default_course", "track_centerline"),
    "camera": ("Camera", "FlyCamera", "frustum_planes", "look_at", "orthographic", "perspective", "track_camera"),
    "objects": ("ObjectSet", "compress_mesh", "make_mesh", "place_objects"),
    "riders": ("RiderSet", "follow_camera"),
    "scene": ("Scene", "SceneFrame"),
    "scene_file": ("SceneFile", "load_scene", "loads_scene"),
})

if TYPE_CHECKING:  # the same names, eagerly, for type checkers and the import graph
    from piste.world.course import default_course, track_centerline  # noqa: F401
    from piste.world.camera import Camera, FlyCamera, frustum_planes, look_at, orthographic, perspective, track_camera  # noqa: F401
    from piste.world.objects import ObjectSet, compress_mesh, make_mesh, place_objects  # noqa: F401
    from piste.world.riders import RiderSet, follow_camera  # noqa: F401
    from piste.world.scene import Scene, SceneFrame  # noqa: F401
    from piste.world.scene_file import SceneFile, load_scene, loads_scene  # noqa: F401

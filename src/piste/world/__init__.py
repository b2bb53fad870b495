from piste.world.course import default_course, track_centerline  # noqa: E402
from piste.world.camera import Camera, FlyCamera, frustum_planes, look_at, orthographic, perspective, track_camera  # noqa: E402
from piste.world.objects import ObjectSet, compress_mesh, make_mesh, place_objects  # noqa: E402
from piste.world.riders import RiderSet, follow_camera  # noqa: E402
from piste.world.scene import Scene, SceneFrame  # noqa: E402
from piste.world.scene_file import SceneFile, load_scene, loads_scene  # noqa: E402

__all__ = [
    "default_course", "track_centerline",
    "Camera", "FlyCamera", "frustum_planes", "look_at", "orthographic", "perspective", "track_camera",
    "ObjectSet", "compress_mesh", "make_mesh", "place_objects",
    "RiderSet", "follow_camera",
    "Scene", "SceneFrame",
    "SceneFile", "load_scene", "loads_scene",
]

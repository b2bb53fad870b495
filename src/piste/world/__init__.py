from piste.world.course import default_course, track_centerline  # noqa: E402
from piste.world.camera import Camera, FlyCamera, frustum_planes, look_at, orthographic, perspective, track_camera  # noqa: E402

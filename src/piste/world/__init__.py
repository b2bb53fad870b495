from piste.world.course import default_course, track_centerline  # noqa: E402

"""The overhead camera and what is made of its frames.

Frame sources (:mod:`.frames`, :mod:`.camera`, :mod:`.netcamera`, :mod:`.camerafaults`); the camera model and its
calibration (:mod:`.cameramodel`, :mod:`.calibrate`); the rendered scene (:mod:`.scene`); marker tracking
(:mod:`.tracker`, :mod:`.framecheck`); the pose observer fed by the tracker (:mod:`.observer`).
"""

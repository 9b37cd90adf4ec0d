"""From a posterior to a picture: cameras (:mod:`~vbgs.render.camera`), splats and PLY
(:mod:`~vbgs.render.splats`), the tiled rasterizer and its independent reference, the
Pallas compositing path, the 2-D image render (:mod:`~vbgs.render.image`), opacity from
evidence, the colour fit, the background estimate and the metrics.

The modules are imported one by one (importing the package imports none of them).
"""

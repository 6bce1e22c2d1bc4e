"""``potflat view``: a finished run's scan and its flat image side by side in a browser page.

* :mod:`potflat.view.scene`: one run as the page sees it (the flat image's pixel grid, the
  relaxed flattening, the position map) and the links between the two views: pixel to
  surface point, surface point (a ray on the vessel) to pixel, the readout, the measure.
* :mod:`potflat.view.display`: the decimated display mesh with the flat coordinates as its
  second texture-coordinate set, and the seam's line on the surface.
* :mod:`potflat.view.tiles`: deep-zoom tiles (DZI) of the painting and the distortion maps.
* :mod:`potflat.view.edits`: the page's edits (seam point, angle window, overlap, painted
  mask) as rollout options, and the rerun with the equivalent command line.
* :mod:`potflat.view.server`: the local HTTP server (127.0.0.1, a free port, a random token).

The page's JavaScript (three.js, three-mesh-bvh, OpenSeadragon, from the npm registry) ships
in ``static/vendor/`` with its licences; the page fetches nothing from the network.
"""

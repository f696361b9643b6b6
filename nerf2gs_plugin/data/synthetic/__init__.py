"""The procedural street scene behind ``ns2gs-data synth-street`` (public API in
:mod:`nerf2gs_plugin.data.synthetic_street`).

  * :mod:`.layout`   -- the static street (boxes, spheres, materials) and the moving cars, in metres;
  * :mod:`.raycast`  -- exact vectorised ray casting and shading of one camera;
  * :mod:`.textures` -- hashed value noise and the surface patterns;
  * :mod:`.poses`    -- training, street-level and bird's-eye camera poses;
  * :mod:`.coverage` -- what the bird's-eye views see that no training view saw at a similar angle;
  * :mod:`.movers`   -- the movers of ``--movers`` and every frame's moving boxes;
  * :mod:`.scene_flow` -- the exact optical flow between two training frames.
"""

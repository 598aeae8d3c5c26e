"""USD (``.usda`` text, ``.usdc`` binary): the whole run as animated prims.

Format sources: Pixar's USD documentation, "UsdGeomPoints" and
"UsdGeomPointBased" (attribute names and types), "UsdGeom: Stage Metrics"
(``upAxis``, ``metersPerUnit``), "UsdStage" time codes (``startTimeCode``,
``endTimeCode``, ``timeCodesPerSecond``) and the ``.usda`` text syntax as
written by USD itself (``#usda 1.0``, layer metadata in parentheses,
``attr.timeSamples = { code: value, ... }``).

What the file holds
-------------------
::

    #usda 1.0
    ( customLayerData, defaultPrim, start/endTimeCode, timeCodesPerSecond,
      framesPerSecond, metersPerUnit = 1, upAxis = "Y" )
    def Xform "<scene>"
    {
        def Points "particles"
        {
            custom uniform string[] animsim:idTable   # the id strings
            float3[]   extent.timeSamples             # bounds incl. widths/2
            int64[]    ids.timeSamples                # row of animsim:idTable
            point3f[]  points.timeSamples             # position, m
            color3f[]  primvars:displayColor          # RGB, vertex interpolation
            float[]    primvars:displayOpacity        # alpha, vertex interpolation
            int[]      primvars:id                    # the same rows as ids (Blender: attribute "id")
            vector3f[] velocities.timeSamples         # m/s (USD: units per second)
            float[]    widths.timeSamples             # diameter = 2 * radius, vertex
        }
    }

Structures keep their shape. When the run has cloth, soft boxes, meshes or
strands (the trajectory header's connectivity), each becomes its own prim
beside ``particles``, named after the structure (sanitised as below):

* cloth, soft box (its outer surface) and mesh structures: ``def Mesh`` with
  ``faceVertexCounts`` / ``faceVertexIndices`` (quads or triangles, wound
  counter-clockwise seen from outside), ``subdivisionScheme = "none"``
  (the faces are the simulated ones, not a control cage),
  ``doubleSided = true``, and time-sampled ``points``, ``velocities``,
  ``extent``; ``animsim:ids`` names the particle behind each point;
* strands: ``def BasisCurves`` with ``type = "linear"``,
  ``curveVertexCounts``, a constant ``widths`` of twice the strand's particle
  radius (:data:`STRAND_RADIUS` when the scene gives none: 5 mm wide) and
  time-sampled ``points``, ``velocities``, ``extent``.

``particles`` then holds only the other particles (listed ones and emitted
ones) and is left out when there are none and no emitters (a scene of rigid
bodies alone has none). With emitters it
also carries ``primvars:age`` (s since birth, vertex interpolation; ``nan``
for particles that were not emitted).

Colour space: scene colours are sRGB (``#rrggbb`` as on the web); USD's
``displayColor`` is read as linear light by Blender, Houdini and usdview,
so it holds the sRGB colour decoded to linear (IEC 61966-2-1). The PLY
export stores the sRGB bytes, which those tools decode the same way, so a
colour looks the same through both.

Every time-sampled attribute has one sample per recorded frame, all at the
same time codes. ``ids`` (int64 in ``UsdGeomPoints``) gives each point's
identity, which is what USD uses to follow points when the count changes
between samples (emitters); its values are rows of the run's id table (header
ids then each frame's ``new_ids``), and the table itself is the
``animsim:idTable`` string array. Importers that drop ``ids`` (Blender brings
primvars in as attributes, not ``ids``) still get each point's row as the
integer primvar ``primvars:id``. A point's width is twice its radius and its
colour its own (the scene's ``radius`` and ``color``, an emitted particle's size
and colour over life), else ``2 * DEFAULT_SIZE`` and opaque white, the rule
every exporter shares (:mod:`animsim.export.look`).

The scene name becomes the root prim's name with every character outside
``[A-Za-z0-9_]`` replaced by ``_`` (and a leading ``_`` before a digit); the
original name is in the prim's ``doc``.

Time codes
----------
When the recorded frames are evenly spaced in time (within
:data:`EVEN_SPACING_RTOL` of the period), frame ``k`` is time code ``k`` and
``timeCodesPerSecond`` is the recorded frame rate ``1 / period`` (snapped to
an integer when within that tolerance). Otherwise (``every=n`` with a
shortened last interval, ``fps`` recording on a step grid that does not
divide the frame period, a dt that does not divide the duration)
``timeCodesPerSecond`` is the sink's ``uneven_rate`` (the scene's recording
rate; default the run's ``fps``, else 24, USD's own default) and the time code
of a frame at time ``t`` is the whole number nearest ``t * rate``: a frame
recorded at the step nearest ``k / fps`` is time code ``k``, so players and
Blender step through whole frames. Only when two frames would share a whole
number is the code ``t * rate`` itself. The exact frame times and steps are
always in ``customLayerData`` (``animsim`` dictionary, ``frameTimes`` and
``frameSteps``), together with the run's ``close`` metadata (status and so on)
but for its timings (``wall_time``, ``compile_time``), which only the
``.meta.json`` sidecar holds, so the same scene and seed give the same bytes.

Binary crate
------------
``-o run.usdc`` (or ``.usd``) writes the same stage in USD's binary crate
format, through usd-core (the ``usd`` extra): the text is assembled next to
the target, read back by usd-core's own parser and exported. The numbers are
then float32 in the file (the schema's types), and a run of 10,000 particles
over 51 frames takes about a quarter of the text's size.

Precision
---------
USD's schema types are single precision (``point3f``, ``vector3f``,
``float``). Numbers are written with Python's ``repr`` of the float64 value,
the shortest text that reads back to the same double, so the file itself
holds the simulation exactly; USD parses the text as a double and rounds
once to float32, which is the same as ``numpy.float32(value)``.

Streaming and atomicity
-----------------------
A ``.usda`` prim must be written in one piece, while frames arrive one by
one. Each attribute's samples therefore go, one line per frame, to its own
temporary file in the target's folder; ``close`` writes the final file under
a temporary name (:class:`animsim.atomic.AtomicFile`), copying the sample
lines in with their time codes, and renames it when whole; then
``<path>.meta.json``, like every trajectory sink. Memory stays
bounded by one frame plus one time and step per frame. ``abort`` removes the
temporary files and leaves no trace.

The package's modules, each named for what it holds: ``text`` (literals, number
lists, time codes and layer metadata), ``prims`` (the time-sampled attributes, the
prims and the rigid bodies) and ``sink`` (:class:`UsdaSink`). Every public name of
theirs is here too.
"""

from __future__ import annotations

from animsim.export.usda.prims import (
    AGE_ATTRIBUTE,
    ATTRIBUTES,
    CURVE_TOPOLOGY,
    MESH_TOPOLOGY,
    SHAPE_ATTRIBUTES,
    VERTEX_INTERPOLATION,
    Attribute,
    BodyPrims,
    Prim,
    body_plan,
)
from animsim.export.usda.sink import (
    GENERATOR,
    ID_TABLE_ATTR,
    META_DICT,
    METERS_PER_UNIT,
    POINTS_PRIM,
    RESERVED_META_KEYS,
    STRAND_RADIUS,
    UP_AXIS,
    USDA_MAGIC,
    UsdaSink,
)
from animsim.export.usda.text import (
    EVEN_SPACING_RTOL,
    FALLBACK_ROOT,
    INDENT,
    USD_DEFAULT_TIME_CODES_PER_SECOND,
    format_floats,
    format_ints,
    format_time_code,
    format_tuples,
    prim_name,
    repeated_list,
    srgb_to_linear,
    time_codes,
    usd_string,
    usd_value_lines,
)

__all__ = [
    "AGE_ATTRIBUTE",
    "ATTRIBUTES",
    "CURVE_TOPOLOGY",
    "EVEN_SPACING_RTOL",
    "FALLBACK_ROOT",
    "GENERATOR",
    "ID_TABLE_ATTR",
    "INDENT",
    "MESH_TOPOLOGY",
    "META_DICT",
    "METERS_PER_UNIT",
    "POINTS_PRIM",
    "RESERVED_META_KEYS",
    "SHAPE_ATTRIBUTES",
    "STRAND_RADIUS",
    "UP_AXIS",
    "USDA_MAGIC",
    "USD_DEFAULT_TIME_CODES_PER_SECOND",
    "VERTEX_INTERPOLATION",
    "Attribute",
    "BodyPrims",
    "Prim",
    "UsdaSink",
    "body_plan",
    "format_floats",
    "format_ints",
    "format_time_code",
    "format_tuples",
    "prim_name",
    "repeated_list",
    "srgb_to_linear",
    "time_codes",
    "usd_string",
    "usd_value_lines",
]

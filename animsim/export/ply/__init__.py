"""PLY point sequences: one binary PLY file per recorded frame.

Format source: Greg Turk, "The PLY Polygon File Format" (Stanford, 1994),
the description every PLY reader follows. A file is an ASCII header (``ply``,
``format``, ``comment``/``obj_info``, ``element``/``property`` lines, each
ending in a line feed, closed by ``end_header``) followed by the element data,
here ``binary_little_endian 1.0``: the rows of each element back to back, every
property in its declared type, no padding.

What a file holds
-----------------
One ``vertex`` element, one row per particle alive in the frame, in the
frame's row order (creation order), with these properties in this order:

=======================  =================  ==================================
property                 PLY type           meaning
=======================  =================  ==================================
``x y z``                ``double``         position, m
``vx vy vz``             ``double``         velocity, m/s
``id``                   ``int``            row of the id table (see below)
``red green blue alpha`` ``uchar``          colour, ``round(255 * c)``
``size``                 ``float``          particle size (radius), m
``radius``               ``float``          the same number, under the name
                                            Blender's point clouds use
=======================  =================  ==================================

A particle's size and colour are its own (the scene's ``radius`` and
``color``, an emitted particle's size and colour over life), else
:data:`DEFAULT_SIZE` and opaque white (:mod:`animsim.export.look`, the rule
every exporter shares). Colours are sRGB bytes (the scene's ``#rrggbb`` values),
which Blender, ParaView and Houdini decode as sRGB; the USD export writes the
same colours decoded to linear light, so both look alike.

Velocity is three scalar properties ``vx vy vz``: PLY has no vector type,
and the only vector names readers know (``nx ny nz``) mean a surface normal,
so putting the velocity there would shade meshes wrongly. Blender 4.1+ brings
them in as three float attributes; combine them in Geometry Nodes, or use the
USD export, where ``velocities`` is a real vector (motion blur included).

Shapes. When the run has structures (the header's connectivity):

* a ``face`` element (``property list uchar int vertex_indices``, the name
  Blender, trimesh, plyfile, Open3D and VTK read) with the faces of every
  cloth (grid quads), soft box (the quads of its outer surface) and mesh
  structure (triangles), wound counter-clockwise seen from outside, indices
  into this file's vertex rows;
* an ``edge`` element (``property int vertex1``, ``property int vertex2``,
  Turk's names) with the segments of every strand.

Loose particles (listed or emitted) are vertices no face uses.

Empty frames. A frame with no particle (before an emitter's first birth, or
after the last death) would be a file with zero vertices, which Blender,
Open3D and trimesh refuse. Such a frame holds instead one placeholder
vertex at the origin with ``id`` -1, size, radius and alpha 0, and the
header says so (``comment placeholder vertex id -1: this frame has no
particles``). ``id`` -1 is never a row of the id table; drop the vertex by
that test (Blender: Delete Geometry where the ``id`` attribute is below 0).

**double, not float, for positions and velocities.** The data is the
simulation state and must read back bit for bit (the tests compare exactly);
a float32 position of a particle 100 m from the origin is only good to about
8 micrometres, visible as jitter in slow motion. Turk's format lists
``double`` as a regular type, and the readers that matter accept it, then
convert to their own single-precision storage, which costs the viewer nothing
and keeps the file exact:

* Blender 3.6+ (the C++ importer, ``source/blender/io/ply``): its header
  parser knows ``double``/``float64`` and converts to float; ``red green blue
  alpha`` become the colour attribute; since Blender 4.1 every other vertex
  property (``vx``, ``size``, ``id``, ...) becomes a float point attribute.
  Comments and ``obj_info`` lines are skipped. It reports an error for a file
  with no vertices (a frame before an emitter's first particle) and it
  assumes Z up: import with *Up = Y* (animsim is Y up).
* ParaView/VTK (``vtkPLYReader``): reads ``x y z`` of any numeric type into
  float points and ``red green blue`` as point colours; a file without a
  ``face`` element is accepted. Other properties are ignored by older VTK,
  and the points may come without vertex cells (show them with a point
  representation such as Point Gaussian; not checked here).
* Houdini: not checked here.

Blender has a built-in integer ``id`` point attribute; how its importer
treats a PLY property of that name is not checked here.

Tools that insist on ``float`` get it with ``position_type="float"`` (the
velocities follow); that file is then *not* exact.

Files and naming
----------------
``path`` is either a file name ending in ``.ply`` (``out/frames.ply``: the
sequence is ``out/frames_0000.ply``, ``out/frames_0001.ply``, ...) or a
directory (``out/``: ``out/frames_0000.ply``, ...; stem :data:`DEFAULT_STEM`).
An existing directory always counts as a directory. The number is the
0-based index of the recorded frame (not the step; the step is in the
header), zero-padded to a width fixed before the first frame: the digits of
``expected_frames - 1`` but at least :data:`MIN_INDEX_WIDTH`, or
:data:`DEFAULT_INDEX_WIDTH` when no count is given. Should a run record more
frames than announced, the later numbers simply have more digits (readers
that sort numerically, like Blender's sequence tools, still order them).
Missing directories are created (and removed again by ``abort``).

Header comments, one fact per line: ``comment generator animsim <version>``,
``comment scene <name>``, ``comment frame <k>``, ``comment step <step>``,
``comment time <t>`` (``repr`` of the float, so it reads back exactly) and
``comment ids <stem>_ids.txt``.

The id table
------------
PLY has no string type, so ``id`` is the int32 row of the run's id table:
the header's ids followed by every frame's ``new_ids``, in that order. The
table is written at ``close`` to the sidecar ``<stem>_ids.txt`` next to the
frames: UTF-8, one id per line, line ``k`` (0-based) is id ``k``; a backslash,
line feed or carriage return inside an id is written ``\\\\``, ``\\n``, ``\\r``
(:func:`read_ids` undoes it).

Atomicity
---------
Each frame file is written under a temporary name in its folder and renamed
when whole (:class:`animsim.atomic.AtomicFile`); ``abort`` drops the frame in
progress and deletes every file this sink wrote in this run (and the
folders it created, when empty). ``close`` writes the id table and, as every
trajectory sink does, ``<path>.meta.json`` (the path as given: ``frames.ply``
gives ``frames.ply.meta.json``, a directory ``out`` gives ``out.meta.json``),
each atomically. Then frame files of an earlier, longer animsim run with the
same stem (numbers not written this time, header saying ``comment generator
animsim``) are deleted so a sequence importer does not mix two runs; other
files are never touched.

The package's modules, each named for what it holds: ``layout`` (the vertex row, the
names and types, the id sidecar, the frame check), ``sink`` (:class:`PlySequenceSink`)
and ``body_meshes`` (rigid bodies as meshes). Every public name of theirs is here too.
"""

from __future__ import annotations

from animsim.export.ply.body_meshes import with_body_meshes
from animsim.export.ply.layout import (
    COLOR_FIELDS,
    COLOR_MAX,
    COLOR_TYPE,
    DEFAULT_INDEX_WIDTH,
    DEFAULT_STEM,
    EDGE_ELEMENT,
    FACE_ELEMENT,
    FORMAT_LINE,
    GENERATOR,
    HEADER_PROBE_BYTES,
    ID_TYPE,
    IDS_SIDECAR_SUFFIX,
    INT32_MAX,
    MIN_INDEX_WIDTH,
    PLACEHOLDER_COMMENT,
    PLACEHOLDER_ID,
    PLY_SUFFIX,
    POSITION_FIELDS,
    POSITION_TYPES,
    SIZE_TYPE,
    VELOCITY_FIELDS,
    comment_text,
    escape_id,
    index_width,
    placeholder_frame,
    property_lines,
    read_ids,
    rgba_bytes,
    sequence_layout,
    unescape_id,
    validate_frame,
    vertex_dtype,
)
from animsim.export.ply.sink import PlySequenceSink

# read_ply and PlyFormatError stay importable from here, beside the writer whose frames they read back
from animsim.ply_reader import VERTEX_ELEMENT, PlyFormatError, read_ply

__all__ = [
    "COLOR_FIELDS",
    "COLOR_MAX",
    "COLOR_TYPE",
    "DEFAULT_INDEX_WIDTH",
    "DEFAULT_STEM",
    "EDGE_ELEMENT",
    "FACE_ELEMENT",
    "FORMAT_LINE",
    "GENERATOR",
    "HEADER_PROBE_BYTES",
    "IDS_SIDECAR_SUFFIX",
    "ID_TYPE",
    "INT32_MAX",
    "MIN_INDEX_WIDTH",
    "PLACEHOLDER_COMMENT",
    "PLACEHOLDER_ID",
    "PLY_SUFFIX",
    "POSITION_FIELDS",
    "POSITION_TYPES",
    "SIZE_TYPE",
    "VELOCITY_FIELDS",
    "VERTEX_ELEMENT",
    "PlyFormatError",
    "PlySequenceSink",
    "comment_text",
    "escape_id",
    "index_width",
    "placeholder_frame",
    "property_lines",
    "read_ids",
    "read_ply",
    "rgba_bytes",
    "sequence_layout",
    "unescape_id",
    "validate_frame",
    "vertex_dtype",
    "with_body_meshes",
]

"""Rendering. In: a scene type, a seed and a `RenderConfig`. Out: a render entry
`renders/<scene>-s<seed>-<key>/` (six 8-bit views, their ground-truth layers, the rig as
a COLMAP text model, `meta.json` with checksums), cached by a content hash.

`config` holds the settings, `variant` chooses a Mitsuba variant safely, `mitsuba` is the
only module that talks to Mitsuba, `entry` is the cache, `gallery` a contact sheet.
"""

//! The JSON Schemas of the recorded messages (dextrain's and Foxglove's), written into the MCAP.

use super::*;

pub(super) const JSON_SCHEMA_DIALECT: &str = "https://json-schema.org/draft/2020-12/schema";

/// A number, or null for a non-finite value.
pub(super) fn num_or_null(description: &str) -> Value {
    json!({ "type": ["number", "null"], "description": description })
}

pub(super) fn dx_time(description: &str) -> Value {
    json!({
        "type": "object",
        "title": "time",
        "description": description,
        "properties": {
            "sec": { "type": "integer", "minimum": 0 },
            "nsec": { "type": "integer", "minimum": 0, "maximum": 999_999_999 }
        },
        "required": ["sec", "nsec"],
        "additionalProperties": false
    })
}

pub(super) fn dx_xyz(title: &str, description: &str) -> Value {
    json!({
        "title": title,
        "description": description,
        "type": "object",
        "properties": {
            "x": num_or_null("x"),
            "y": num_or_null("y"),
            "z": num_or_null("z")
        },
        "required": ["x", "y", "z"],
        "additionalProperties": false
    })
}

pub(super) fn dx_pose(description: &str) -> Value {
    json!({
        "title": "dextrain.Pose",
        "description": description,
        "type": "object",
        "properties": {
            "x": num_or_null("Position x (m)"),
            "y": num_or_null("Position y (m)"),
            "z": num_or_null("Position z (m)"),
            "qx": num_or_null("Orientation quaternion x"),
            "qy": num_or_null("Orientation quaternion y"),
            "qz": num_or_null("Orientation quaternion z"),
            "qw": num_or_null("Orientation quaternion w")
        },
        "required": ["x", "y", "z", "qx", "qy", "qz", "qw"],
        "additionalProperties": false
    })
}

pub(super) fn dx_joint_array(description: &str) -> Value {
    json!({ "type": "array", "items": num_or_null("value"), "description": description })
}

pub(super) fn hand_state_schema() -> Value {
    json!({
        "$schema": JSON_SCHEMA_DIALECT,
        "title": SCHEMA_HAND_STATE,
        "description": "Joint state of the simulated hand at one recorded time. The arrays are in joint_names order (the hand's movable joints, mimic followers included). Non-finite values are null.",
        "type": "object",
        "properties": {
            "timestamp": dx_time("Simulated time of the frame"),
            "t": { "type": "number", "description": "Simulated time (s)" },
            "joint_names": { "type": "array", "items": { "type": "string" }, "description": "Joint names" },
            "position": dx_joint_array("Joint positions (rad)"),
            "velocity": dx_joint_array("Joint velocities (rad/s)"),
            "target": dx_joint_array("Joint position targets (rad)")
        },
        "required": ["timestamp", "t", "joint_names", "position", "velocity", "target"],
        "additionalProperties": false
    })
}

pub(super) fn poses_schema() -> Value {
    json!({
        "$schema": JSON_SCHEMA_DIALECT,
        "title": SCHEMA_POSES,
        "description": "World poses (z up, metres, unit quaternions) of the wrist (root link), the object and, when there is one, the reference object pose. Non-finite values are null.",
        "type": "object",
        "properties": {
            "timestamp": dx_time("Simulated time of the frame"),
            "t": { "type": "number", "description": "Simulated time (s)" },
            "wrist": dx_pose("Wrist (root link) pose"),
            "object": dx_pose("Object pose"),
            "object_ref": {
                "anyOf": [dx_pose("Reference object pose"), { "type": "null" }],
                "description": "Reference object pose, null when there is none"
            }
        },
        "required": ["timestamp", "t", "wrist", "object", "object_ref"],
        "additionalProperties": false
    })
}

pub(super) fn contacts_schema() -> Value {
    json!({
        "$schema": JSON_SCHEMA_DIALECT,
        "title": SCHEMA_CONTACTS,
        "description": "Contacts at one recorded time, in the world frame. Non-finite values are null.",
        "type": "object",
        "properties": {
            "timestamp": dx_time("Simulated time of the frame"),
            "t": { "type": "number", "description": "Simulated time (s)" },
            "contacts": {
                "type": "array",
                "description": "Contacts",
                "items": {
                    "title": "dextrain.Contact",
                    "description": "One contact between the hand and the object, the hand and the table, or the object and the table",
                    "type": "object",
                    "properties": {
                        "kind": { "type": "string", "enum": ["hand_object", "hand_table", "object_table"], "description": "Pair in contact (first body, second body)" },
                        "index": { "type": "integer", "minimum": 0, "description": "Hand collider index for hand contacts, object support-point index for object_table" },
                        "link": { "type": ["string", "null"], "description": "Name of the hand link owning the collider (hand contacts), else null" },
                        "pos": dx_xyz("dextrain.Vector3", "Contact point (m)"),
                        "normal": dx_xyz("dextrain.Vector3", "Unit normal from the second body to the first"),
                        "depth": num_or_null("Penetration depth (m)"),
                        "force": dx_xyz("dextrain.Vector3", "Total contact force on the first body (N)")
                    },
                    "required": ["kind", "index", "link", "pos", "normal", "depth", "force"],
                    "additionalProperties": false
                }
            }
        },
        "required": ["timestamp", "t", "contacts"],
        "additionalProperties": false
    })
}

// Foxglove schemas, in the form published in foxglove/schemas `schemas/jsonschema/*.json`: a nested
// message takes the field's description; arrays of messages keep the message's own description.

pub(super) fn fg_time(description: &str) -> Value {
    json!({
        "type": "object",
        "title": "time",
        "properties": {
            "sec": { "type": "integer", "minimum": 0 },
            "nsec": { "type": "integer", "minimum": 0, "maximum": 999_999_999 }
        },
        "description": description
    })
}

pub(super) fn fg_duration(description: &str) -> Value {
    json!({
        "type": "object",
        "title": "duration",
        "properties": {
            "sec": { "type": "integer", "minimum": -2_147_483_648i64, "maximum": 2_147_483_647 },
            "nsec": { "type": "integer", "minimum": 0, "maximum": 999_999_999 }
        },
        "description": description
    })
}

pub(super) fn fg_number(description: &str) -> Value {
    json!({ "type": "number", "description": description })
}

pub(super) fn fg_message(title: &str, description: &str, properties: Value) -> Value {
    json!({ "title": title, "description": description, "type": "object", "properties": properties })
}

pub(super) fn fg_array(items: Value, description: &str) -> Value {
    json!({ "type": "array", "items": items, "description": description })
}

pub(super) fn fg_vector3(description: &str) -> Value {
    fg_message(
        "foxglove.Vector3",
        description,
        json!({
            "x": fg_number("x coordinate length"),
            "y": fg_number("y coordinate length"),
            "z": fg_number("z coordinate length")
        }),
    )
}

pub(super) fn fg_point3(description: &str) -> Value {
    fg_message(
        "foxglove.Point3",
        description,
        json!({
            "x": fg_number("x coordinate position"),
            "y": fg_number("y coordinate position"),
            "z": fg_number("z coordinate position")
        }),
    )
}

pub(super) fn fg_quaternion(description: &str) -> Value {
    fg_message(
        "foxglove.Quaternion",
        description,
        json!({
            "x": fg_number("x value"),
            "y": fg_number("y value"),
            "z": fg_number("z value"),
            "w": fg_number("w value")
        }),
    )
}

pub(super) fn fg_pose(description: &str) -> Value {
    fg_message(
        "foxglove.Pose",
        description,
        json!({
            "position": fg_vector3("Point denoting position in 3D space"),
            "orientation": fg_quaternion("Quaternion denoting orientation in 3D space")
        }),
    )
}

pub(super) fn fg_color(description: &str) -> Value {
    fg_message(
        "foxglove.Color",
        description,
        json!({
            "r": fg_number("Red value between 0 and 1"),
            "g": fg_number("Green value between 0 and 1"),
            "b": fg_number("Blue value between 0 and 1"),
            "a": fg_number("Alpha value between 0 and 1")
        }),
    )
}

pub(super) const INDICES_DESCRIPTION: &str = "Indices into the `points` and `colors` attribute arrays, which can be used to avoid duplicating attribute data.\n\nIf omitted or empty, indexing will not be used. This default behavior is equivalent to specifying [0, 1, ..., N-1] for the indices (where N is the number of `points` provided).";

pub(super) fn frame_transforms_schema() -> Value {
    let transform = fg_message(
        "foxglove.FrameTransform",
        "A transform between two reference frames in 3D space",
        json!({
            "timestamp": fg_time("Timestamp of transform"),
            "parent_frame_id": { "type": "string", "description": "Name of the parent frame" },
            "child_frame_id": { "type": "string", "description": "Name of the child frame" },
            "translation": fg_vector3("Translation component of the transform"),
            "rotation": fg_quaternion("Rotation component of the transform")
        }),
    );
    json!({
        "title": "foxglove.FrameTransforms",
        "description": "An array of FrameTransform messages",
        "$comment": "Generated by https://github.com/foxglove/schemas",
        "type": "object",
        "properties": {
            "transforms": fg_array(transform, "Array of transforms")
        }
    })
}

pub(super) fn scene_update_schema() -> Value {
    let deletion = fg_message(
        "foxglove.SceneEntityDeletion",
        "Command to remove previously published entities",
        json!({
            "timestamp": fg_time("Timestamp of the deletion. Only matching entities earlier than this timestamp will be deleted."),
            "type": {
                "title": "foxglove.SceneEntityDeletionType",
                "description": "Type of deletion action to perform",
                "oneOf": [
                    { "title": "MATCHING_ID", "const": 0, "description": "Delete the existing entity on the same topic that has the provided `id`" },
                    { "title": "ALL", "const": 1, "description": "Delete all existing entities on the same topic" }
                ]
            },
            "id": { "type": "string", "description": "Identifier which must match if `type` is `MATCHING_ID`." }
        }),
    );
    let key_value = fg_message(
        "foxglove.KeyValuePair",
        "A key with its associated value",
        json!({
            "key": { "type": "string", "description": "Key" },
            "value": { "type": "string", "description": "Value" }
        }),
    );
    let arrow = fg_message(
        "foxglove.ArrowPrimitive",
        "A primitive representing an arrow",
        json!({
            "pose": fg_pose("Position of the arrow's tail and orientation of the arrow. Identity orientation means the arrow points in the +x direction."),
            "shaft_length": fg_number("Length of the arrow shaft"),
            "shaft_diameter": fg_number("Diameter of the arrow shaft"),
            "head_length": fg_number("Length of the arrow head"),
            "head_diameter": fg_number("Diameter of the arrow head"),
            "color": fg_color("Color of the arrow")
        }),
    );
    let cube = fg_message(
        "foxglove.CubePrimitive",
        "A primitive representing a cube or rectangular prism",
        json!({
            "pose": fg_pose("Position of the center of the cube and orientation of the cube"),
            "size": fg_vector3("Size of the cube along each axis"),
            "color": fg_color("Color of the cube")
        }),
    );
    let sphere = fg_message(
        "foxglove.SpherePrimitive",
        "A primitive representing a sphere or ellipsoid",
        json!({
            "pose": fg_pose("Position of the center of the sphere and orientation of the sphere"),
            "size": fg_vector3("Size (diameter) of the sphere along each axis"),
            "color": fg_color("Color of the sphere")
        }),
    );
    let cylinder = fg_message(
        "foxglove.CylinderPrimitive",
        "A primitive representing a cylinder, elliptic cylinder, or truncated cone",
        json!({
            "pose": fg_pose("Position of the center of the cylinder and orientation of the cylinder. The flat face(s) are perpendicular to the z-axis."),
            "size": fg_vector3("Size of the cylinder's bounding box"),
            "bottom_scale": fg_number("0-1, ratio of the diameter of the cylinder's bottom face (min z) to the bottom of the bounding box"),
            "top_scale": fg_number("0-1, ratio of the diameter of the cylinder's top face (max z) to the top of the bounding box"),
            "color": fg_color("Color of the cylinder")
        }),
    );
    let line = fg_message(
        "foxglove.LinePrimitive",
        "A primitive representing a series of points connected by lines",
        json!({
            "type": {
                "title": "foxglove.LineType",
                "description": "Drawing primitive to use for lines",
                "oneOf": [
                    { "title": "LINE_STRIP", "const": 0, "description": "Connected line segments: 0-1, 1-2, ..., (n-1)-n" },
                    { "title": "LINE_LOOP", "const": 1, "description": "Closed polygon: 0-1, 1-2, ..., (n-1)-n, n-0" },
                    { "title": "LINE_LIST", "const": 2, "description": "Individual line segments: 0-1, 2-3, 4-5, ..." }
                ]
            },
            "pose": fg_pose("Origin of lines relative to reference frame"),
            "thickness": fg_number("Line thickness"),
            "scale_invariant": { "type": "boolean", "description": "Indicates whether `thickness` is a fixed size in screen pixels (true), or specified in world coordinates and scales with distance from the camera (false)" },
            "points": fg_array(fg_point3("A point representing a position in 3D space"), "Points along the line"),
            "color": fg_color("Solid color to use for the whole line. One of `color` or `colors` must be provided."),
            "colors": fg_array(fg_color("A color in RGBA format"), "Per-point colors (if specified, must have the same length as `points`). One of `color` or `colors` must be provided."),
            "indices": { "type": "array", "items": { "type": "integer", "minimum": 0 }, "description": INDICES_DESCRIPTION }
        }),
    );
    let triangles = fg_message(
        "foxglove.TriangleListPrimitive",
        "A primitive representing a set of triangles or a surface tiled by triangles",
        json!({
            "pose": fg_pose("Origin of triangles relative to reference frame"),
            "points": fg_array(fg_point3("A point representing a position in 3D space"), "Vertices to use for triangles, interpreted as a list of triples (0-1-2, 3-4-5, ...)"),
            "color": fg_color("Solid color to use for the whole shape. One of `color` or `colors` must be provided."),
            "colors": fg_array(fg_color("A color in RGBA format"), "Per-vertex colors (if specified, must have the same length as `points`). One of `color` or `colors` must be provided."),
            "indices": { "type": "array", "items": { "type": "integer", "minimum": 0 }, "description": INDICES_DESCRIPTION }
        }),
    );
    let text = fg_message(
        "foxglove.TextPrimitive",
        "A primitive representing a text label",
        json!({
            "pose": fg_pose("Position of the center of the text box and orientation of the text. Identity orientation means the text is oriented in the xy-plane and flows from -x to +x."),
            "billboard": { "type": "boolean", "description": "Whether the text should respect `pose.orientation` (false) or always face the camera (true)" },
            "font_size": fg_number("Font size (height of one line of text)"),
            "scale_invariant": { "type": "boolean", "description": "Indicates whether `font_size` is a fixed size in screen pixels (true), or specified in world coordinates and scales with distance from the camera (false)" },
            "color": fg_color("Color of the text"),
            "text": { "type": "string", "description": "Text" }
        }),
    );
    let model = fg_message(
        "foxglove.ModelPrimitive",
        "A primitive representing a 3D model file loaded from an external URL or embedded data",
        json!({
            "pose": fg_pose("Origin of model relative to reference frame"),
            "scale": fg_vector3("Scale factor to apply to the model along each axis"),
            "color": fg_color("Solid color to use for the whole model if `override_color` is true."),
            "override_color": { "type": "boolean", "description": "Whether to use the color specified in `color` instead of any materials embedded in the original model." },
            "url": { "type": "string", "description": "URL pointing to model file. One of `url` or `data` should be provided." },
            "media_type": { "type": "string", "description": "[Media type](https://developer.mozilla.org/en-US/docs/Web/HTTP/Basics_of_HTTP/MIME_types) of embedded model (e.g. `model/gltf-binary`). Required if `data` is provided instead of `url`. Overrides the inferred media type if `url` is provided." },
            "data": { "type": "string", "contentEncoding": "base64", "description": "Embedded model. One of `url` or `data` should be provided. If `data` is provided, `media_type` must be set to indicate the type of the data." }
        }),
    );
    let entity = fg_message(
        "foxglove.SceneEntity",
        "A visual element in a 3D scene. An entity may be composed of multiple primitives which all share the same frame of reference.",
        json!({
            "timestamp": fg_time("Timestamp of the entity"),
            "frame_id": { "type": "string", "description": "Frame of reference" },
            "id": { "type": "string", "description": "Identifier for the entity. A entity will replace any prior entity on the same topic with the same `id`." },
            "lifetime": fg_duration("Length of time (relative to `timestamp`) after which the entity should be automatically removed. Zero value indicates the entity should remain visible until it is replaced or deleted."),
            "frame_locked": { "type": "boolean", "description": "Whether the entity should keep its location in the fixed frame (false) or follow the frame specified in `frame_id` as it moves relative to the fixed frame (true)" },
            "metadata": fg_array(key_value, "Additional user-provided metadata associated with the entity. Keys must be unique."),
            "arrows": fg_array(arrow, "Arrow primitives"),
            "cubes": fg_array(cube, "Cube primitives"),
            "spheres": fg_array(sphere, "Sphere primitives"),
            "cylinders": fg_array(cylinder, "Cylinder primitives"),
            "lines": fg_array(line, "Line primitives"),
            "triangles": fg_array(triangles, "Triangle list primitives"),
            "texts": fg_array(text, "Text primitives"),
            "models": fg_array(model, "Model primitives")
        }),
    );
    json!({
        "title": "foxglove.SceneUpdate",
        "description": "An update to the entities displayed in a 3D scene",
        "$comment": "Generated by https://github.com/foxglove/schemas",
        "type": "object",
        "properties": {
            "deletions": fg_array(deletion, "Scene entities to delete"),
            "entities": fg_array(entity, "Scene entities to add or replace")
        }
    })
}

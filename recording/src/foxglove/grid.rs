//! The map builder's map (`nerve::MapCells`: a [`MapHeader`] and the cells
//! the robot has been in) as a `foxglove.Grid`, for the 3D panel: a dense
//! grid over the map's bounds in the world frame, one cell of the grid per
//! cell of the map.
//!
//! Each grid cell has two fields:
//!
//! * `seen` (uint8): 1 for a cell the robot has been in, 0 for one it has
//!   not (`docs/foxglove/explore.json` draws it with a gradient from
//!   transparent to blue);
//! * `visits` (uint8): times the robot entered the cell, at most 255.
//!
//! Rows go along +y, columns along +x; the grid's pose is the corner of
//! cell `(min_ix, min_iy)`: `origin + (min_ix, min_iy) × cell_m`.
//!
//! [`MapHeader`]: shm_schemas::payloads::MapHeader

use super::{base64, time_of};
use serde_json::{Value, json};

/// The type name of the map builder's map.
pub const MAP_TYPE: &str = "nerve::Seq<nerve::MapCell, nerve::MapHeader>";
/// Foxglove's schema name.
pub const GRID: &str = "foxglove.Grid";
/// The frame the map is in: the pose's world.
pub const MAP_FRAME: &str = "world";
/// The most grid cells a map is drawn with (its bounds' area); a map of
/// more is not sent (a grid of 2 MB, 2.7 MB of base64).
pub const MAX_GRID_CELLS: i64 = 1 << 20;

/// Bytes per grid cell: `seen`, `visits`.
const CELL_STRIDE: i64 = 2;
/// `foxglove.PackedElementField`'s numeric type `UINT8`.
const UINT8: u8 = 1;

/// The JSON Schema of `foxglove.Grid` in JSON (bytes as base64).
pub fn grid_json_schema() -> Value {
    let vector = |fields: &[&str]| {
        let props: serde_json::Map<String, Value> =
            fields.iter().map(|f| ((*f).to_owned(), json!({ "type": "number" }))).collect();
        json!({ "type": "object", "properties": props })
    };
    json!({
        "title": GRID,
        "type": "object",
        "properties": {
            "timestamp": super::time_schema(),
            "frame_id": { "type": "string" },
            "pose": {
                "type": "object",
                "properties": { "position": vector(&["x", "y", "z"]), "orientation": vector(&["x", "y", "z", "w"]) },
            },
            "column_count": { "type": "integer" },
            "cell_size": vector(&["x", "y"]),
            "row_stride": { "type": "integer" },
            "cell_stride": { "type": "integer" },
            "fields": {
                "type": "array",
                "items": {
                    "type": "object",
                    "properties": {
                        "name": { "type": "string" },
                        "offset": { "type": "integer" },
                        "type": { "type": "integer" },
                    },
                },
            },
            "data": { "type": "string", "contentEncoding": "base64" },
        },
    })
}

/// A map sample (`{ header: {...}, items: [...] }`, as its schema decodes
/// it) as a `foxglove.Grid` at `unix_ns`; `None` for a map without cells,
/// one whose bounds are not a grid of at most [`MAX_GRID_CELLS`], or a
/// sample that lacks a field.
pub fn map_to_grid(sample: &Value, unix_ns: u64) -> Option<Value> {
    let header = sample.get("header")?;
    let int = |v: &Value, k: &str| v.get(k).and_then(Value::as_i64);
    let num = |k: &str| header.get(k).and_then(Value::as_f64);
    let cell_m = num("cell_m").filter(|c| c.is_finite() && *c > 0.0)?;
    let (origin_x, origin_y) = (num("origin_x")?, num("origin_y")?);
    let (min_ix, min_iy) = (int(header, "min_ix")?, int(header, "min_iy")?);
    let (max_ix, max_iy) = (int(header, "max_ix")?, int(header, "max_iy")?);
    let items = sample.get("items")?.as_array()?;
    if items.is_empty() {
        return None;
    }
    let cols = max_ix.checked_sub(min_ix)?.checked_add(1).filter(|c| *c > 0)?;
    let rows = max_iy.checked_sub(min_iy)?.checked_add(1).filter(|r| *r > 0)?;
    let cells = cols.checked_mul(rows).filter(|n| *n <= MAX_GRID_CELLS)?;
    let row_stride = cols.checked_mul(CELL_STRIDE)?;
    // every cell unseen, then the seen ones
    let mut data = vec![0u8; usize::try_from(cells.checked_mul(CELL_STRIDE)?).ok()?];
    for c in items {
        let (Some(ix), Some(iy)) = (int(c, "ix"), int(c, "iy")) else { continue };
        let (col, row) = (ix.checked_sub(min_ix)?, iy.checked_sub(min_iy)?);
        if !(0..cols).contains(&col) || !(0..rows).contains(&row) {
            // a cell outside the header's bounds: a map that contradicts itself
            return None;
        }
        let at = usize::try_from(row.checked_mul(row_stride)?.checked_add(col.checked_mul(CELL_STRIDE)?)?).ok()?;
        let visits = c.get("visits").and_then(Value::as_u64).unwrap_or(1);
        let slot = data.get_mut(at..at.checked_add(2)?)?;
        slot.copy_from_slice(&[1, u8::try_from(visits).unwrap_or(u8::MAX)]);
    }
    Some(json!({
        "timestamp": time_of(unix_ns),
        "frame_id": MAP_FRAME,
        "pose": {
            "position": {
                "x": origin_x + min_ix as f64 * cell_m,
                "y": origin_y + min_iy as f64 * cell_m,
                "z": 0.0,
            },
            "orientation": { "x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0 },
        },
        "column_count": cols,
        "cell_size": { "x": cell_m, "y": cell_m },
        "row_stride": row_stride,
        "cell_stride": CELL_STRIDE,
        "fields": [
            { "name": "seen", "offset": 0, "type": UINT8 },
            { "name": "visits", "offset": 1, "type": UINT8 },
        ],
        "data": base64(&data),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(cells: &[(i64, i64, u64)], bounds: (i64, i64, i64, i64)) -> Value {
        let (min_ix, min_iy, max_ix, max_iy) = bounds;
        json!({
            "header": {
                "stamp_ns": 1, "cell_m": 0.5, "origin_x": -1.0, "origin_y": 2.0,
                "min_ix": min_ix, "min_iy": min_iy, "max_ix": max_ix, "max_iy": max_iy,
                "count": cells.len(), "revision": 3, "max_cells": 40000, "full": 0,
            },
            "items": cells.iter().map(|(ix, iy, v)| json!({
                "last_seen_ns": 1, "ix": ix, "iy": iy, "x": 0.0, "y": 0.0, "visits": v, "flags": 1,
            })).collect::<Vec<_>>(),
        })
    }

    fn unbase64(text: &str) -> Vec<u8> {
        const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
        let mut bits = 0u32;
        let mut n = 0;
        let mut out = Vec::new();
        for c in text.bytes().filter(|c| *c != b'=') {
            let v = ALPHABET.iter().position(|a| *a == c).expect("base64") as u32;
            bits = bits << 6 | v;
            n += 6;
            if n >= 8 {
                n -= 8;
                out.push((bits >> n) as u8);
            }
        }
        out
    }

    #[test]
    fn a_map_is_a_dense_grid_of_seen_and_unknown_cells() {
        // cells (-1, 3), (0, 3) and (1, 4): 3 columns, 2 rows, corner at cell (-1, 3)
        let g = map_to_grid(&map(&[(-1, 3, 2), (0, 3, 1), (1, 4, 300)], (-1, 3, 1, 4)), 5_000_000_001).expect("a grid");
        assert_eq!(g["timestamp"], json!({ "sec": 5, "nsec": 1 }));
        assert_eq!(g["frame_id"], "world");
        assert_eq!(g["column_count"], 3);
        assert_eq!((g["cell_stride"].as_i64(), g["row_stride"].as_i64()), (Some(2), Some(6)));
        assert_eq!(g["cell_size"], json!({ "x": 0.5, "y": 0.5 }));
        assert_eq!(g["pose"]["position"], json!({ "x": -1.5, "y": 3.5, "z": 0.0 }));
        assert_eq!(g["fields"][0], json!({ "name": "seen", "offset": 0, "type": 1 }));
        assert_eq!(g["fields"][1], json!({ "name": "visits", "offset": 1, "type": 1 }));
        let data = unbase64(g["data"].as_str().expect("data"));
        // row 0 (iy 3): seen 2 visits, seen 1 visit, unseen; row 1 (iy 4): unseen, unseen, seen 255+
        assert_eq!(data, [1, 2, 1, 1, 0, 0, 0, 0, 0, 0, 1, 255]);
    }

    #[test]
    fn an_empty_huge_or_contradictory_map_is_no_grid() {
        assert!(map_to_grid(&map(&[], (0, 0, 0, 0)), 0).is_none(), "no cells");
        assert!(map_to_grid(&map(&[(0, 0, 1), (5000, 5000, 1)], (0, 0, 5000, 5000)), 0).is_none(), "25 M cells");
        assert!(map_to_grid(&map(&[(7, 0, 1)], (0, 0, 1, 1)), 0).is_none(), "a cell out of bounds");
        assert!(map_to_grid(&map(&[(0, 0, 1)], (1, 0, 0, 0)), 0).is_none(), "min past max");
        assert!(map_to_grid(&json!({ "items": [] }), 0).is_none(), "no header");
        let g = map_to_grid(&map(&[(0, 0, 1)], (0, 0, 0, 0)), 0).expect("one cell");
        assert_eq!(unbase64(g["data"].as_str().expect("data")), [1, 1]);
    }

    #[test]
    fn the_map_type_is_the_map_builders() {
        use shm_schemas::schema::Described as _;
        assert_eq!(shm_schemas::payloads::MapCells::schema().type_name, MAP_TYPE);
        assert_eq!(grid_json_schema()["title"], GRID);
    }
}

//! Recordings for viewers that read JSON (Foxglove, Lichtblick): a nerve
//! [`Schema`] as a JSON Schema (MCAP schema encoding [`SCHEMA_ENCODING`]),
//! and messages as JSON (message encoding [`MESSAGE_ENCODING`]), decoded
//! from the raw bytes through the schema (`nerve export --json`). The raw
//! recording stays the record: JSON cannot give back a sample bit-exact.

use serde_json::{Value, json};
use shm_schemas::Schema;
use shm_schemas::schema::{Kind, Primitive};

/// MCAP schema encoding of a JSON Schema.
pub const SCHEMA_ENCODING: &str = "jsonschema";
/// MCAP message encoding of JSON messages.
pub const MESSAGE_ENCODING: &str = "json";

/// The JSON Schema of the JSON that [`shm_schemas::schema::Value`] prints
/// for samples of `schema`.
pub fn json_schema(schema: &Schema) -> Value {
    let mut v = of(schema);
    if let Some(o) = v.as_object_mut() {
        o.insert("$schema".into(), json!("https://json-schema.org/draft/2020-12/schema"));
        o.insert("title".into(), json!(schema.type_name));
    }
    v
}

fn of(schema: &Schema) -> Value {
    match &schema.kind {
        Kind::Primitive { primitive } => match primitive {
            Primitive::F32 | Primitive::F64 => json!({ "type": "number" }),
            Primitive::Bool => json!({ "type": "boolean" }),
            _ => json!({ "type": "integer" }),
        },
        Kind::Array { len, element } => {
            json!({ "type": "array", "items": of(element), "minItems": len, "maxItems": len })
        }
        Kind::String { capacity } => json!({ "type": "string", "maxLength": capacity }),
        Kind::Struct { fields } => {
            let properties: serde_json::Map<String, Value> =
                fields.iter().map(|f| (f.name.clone(), of(&f.schema))).collect();
            let required: Vec<&str> = fields.iter().map(|f| f.name.as_str()).collect();
            json!({ "type": "object", "title": schema.type_name, "properties": properties, "required": required })
        }
        // a sample of any length: its header, then an array of its elements
        Kind::Sequence { header, element } => {
            use shm_schemas::seq::{HEADER_FIELD, ITEMS_FIELD};
            json!({
                "type": "object",
                "title": schema.type_name,
                "properties": { HEADER_FIELD: of(header), ITEMS_FIELD: { "type": "array", "items": of(element) } },
                "required": [HEADER_FIELD, ITEMS_FIELD],
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shm_schemas::Described;
    use shm_schemas::payloads::Tick;

    #[test]
    fn a_payload_becomes_an_object_of_its_fields() {
        let s = json_schema(&Tick::schema());
        assert_eq!(s["type"], "object");
        assert_eq!(s["title"], "nerve::Tick");
        assert_eq!(s["properties"]["seq"]["type"], "integer");
        assert_eq!(s["required"], json!(["seq", "stamp_ns"]));
    }

    #[test]
    fn a_sequence_becomes_its_header_and_an_array_of_any_length() {
        let s = json_schema(&shm_schemas::Seq::<f32, Tick>::schema());
        assert_eq!(s["properties"]["header"]["properties"]["seq"]["type"], "integer");
        assert_eq!(s["properties"]["items"], json!({ "type": "array", "items": { "type": "number" } }));
        assert!(s["properties"]["items"].get("maxItems").is_none(), "any length");
    }
}

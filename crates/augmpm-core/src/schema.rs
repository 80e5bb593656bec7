//! Checks a scene value (JSON) against the JSON Schema of the scene types, naming the dotted key of
//! the first problem: unknown and missing keys, types, the number of items, ranges, the names of
//! choices. The schema is derived from the types themselves (`schemars`), where each key is declared
//! once with its doc line, default, range and unit (`scene.rs`, `material/`); the Python package
//! builds its scene models from the same schema.
//!
//! Only the parts of JSON Schema the derived schema uses are read: `$ref`, `type` (with `null` for
//! optional keys), `properties`, `required`, `items`, `minItems`/`maxItems`, `oneOf` (choices of
//! `const` strings, or objects told apart by the `const` of a tag key), `anyOf` (any one of its options),
//! and the bounds `minimum`, `maximum`, `exclusiveMinimum`, `exclusiveMaximum`. Every object is
//! closed: a key it does not declare is refused. Numbers must be finite.

use serde_json::{Map, Value};

/// The first problem found: the dotted key (`bodies[0].material.poisson_ratio`) and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Invalid {
    pub key: String,
    pub reason: String,
}

fn invalid(key: &str, reason: impl Into<String>) -> Invalid {
    Invalid { key: if key.is_empty() { "scene".into() } else { key.into() }, reason: reason.into() }
}

/// Checks `value` against `root`, a schema whose `$defs` hold the types it refers to.
pub fn check(root: &Value, value: &Value) -> Result<(), Invalid> {
    walk(root, root, value, "")
}

fn child(key: &str, name: &str) -> String {
    if key.is_empty() {
        name.to_string()
    } else {
        format!("{key}.{name}")
    }
}

/// The schema a `$ref` (`#/$defs/Name`) points at.
fn resolve<'a>(root: &'a Value, reference: &str) -> &'a Value {
    let name = reference.rsplit('/').next().unwrap_or_default();
    root.get("$defs").and_then(|d| d.get(name)).unwrap_or_else(|| panic!("the scene schema has no {reference}"))
}

fn walk(root: &Value, schema: &Value, value: &Value, key: &str) -> Result<(), Invalid> {
    if let Some(reference) = schema.get("$ref").and_then(Value::as_str) {
        walk(root, resolve(root, reference), value, key)?;
    }
    if let Some(options) = schema.get("anyOf").and_then(Value::as_array) {
        // Any one of the options (an optional key: null, or its type).
        if value.is_null() && options.iter().any(|o| o.get("type") == Some(&Value::from("null"))) {
            return Ok(());
        }
        let others: Vec<&Value> = options.iter().filter(|o| o.get("type") != Some(&Value::from("null"))).collect();
        let errors: Vec<Invalid> = others.iter().filter_map(|o| walk(root, o, value, key).err()).collect();
        if errors.len() == others.len() && !errors.is_empty() {
            // The error of the option of the value's own type (a number out of range), else the first.
            let own = others.iter().position(|o| types(o).iter().any(|t| kind_of(value) == *t));
            return Err(errors[own.unwrap_or(0)].clone());
        }
    }
    let variant = match schema.get("oneOf").and_then(Value::as_array) {
        Some(options) => choose(options, value, key)?,
        None => None,
    };
    match types(schema).as_slice() {
        [] if variant.is_some() => object(root, schema, variant, value, key),
        [] => Ok(()),
        kinds if value.is_null() && kinds.contains(&"null") => Ok(()),
        kinds if kinds.contains(&"object") => object(root, schema, variant, value, key),
        kinds if kinds.contains(&"array") => array(root, schema, value, key),
        kinds if kinds.contains(&"integer") => integer(schema, value, key),
        kinds if kinds.contains(&"number") => number(schema, value, key),
        kinds if kinds.contains(&"boolean") => match value {
            Value::Bool(_) => Ok(()),
            _ => Err(invalid(key, format!("must be true or false, got {value}"))),
        },
        kinds if kinds.contains(&"string") => match (value, schema.get("const")) {
            (Value::String(_), None) => Ok(()),
            (Value::String(_), Some(c)) if c == value => Ok(()),
            (_, Some(c)) => Err(invalid(key, format!("must be {c}, got {value}"))),
            _ => Err(invalid(key, format!("must be a string, got {value}"))),
        },
        _ => Ok(()),
    }
}

/// The `type` of a schema as a list (`"number"`, or `["number", "null"]` for an optional key).
fn types(schema: &Value) -> Vec<&str> {
    match schema.get("type") {
        Some(Value::String(t)) => vec![t.as_str()],
        Some(Value::Array(ts)) => ts.iter().filter_map(Value::as_str).collect(),
        _ => Vec::new(),
    }
}

/// The JSON Schema type name of a value.
fn kind_of(value: &Value) -> &'static str {
    match value {
        Value::Null => "null",
        Value::Bool(_) => "boolean",
        Value::Number(_) => "number",
        Value::String(_) => "string",
        Value::Array(_) => "array",
        Value::Object(_) => "object",
    }
}

/// The tag key of a `oneOf` of objects: the property that has a `const` in every option.
pub fn tag_of(options: &[Value]) -> Option<&str> {
    let first = options.first()?.get("properties")?.as_object()?;
    first.iter().find_map(|(name, p)| {
        let everywhere = p.get("const").is_some()
            && options
                .iter()
                .all(|o| o.get("properties").and_then(|ps| ps.get(name)).and_then(|p| p.get("const")).is_some());
        everywhere.then_some(name.as_str())
    })
}

fn quoted(values: &[&Value]) -> String {
    values.iter().map(|v| v.to_string()).collect::<Vec<_>>().join(", ")
}

/// Checks a `oneOf`: a choice of strings, or of objects told apart by a tag; returns the chosen object
/// option, whose keys the object check adds to the schema's own.
fn choose<'a>(options: &'a [Value], value: &Value, key: &str) -> Result<Option<&'a Value>, Invalid> {
    if options.iter().all(|o| o.get("const").is_some()) {
        let names: Vec<&Value> = options.iter().filter_map(|o| o.get("const")).collect();
        return if names.contains(&value) {
            Ok(None)
        } else {
            Err(invalid(key, format!("must be one of {}, got {value}", quoted(&names))))
        };
    }
    let Some(tag) = tag_of(options) else { return Ok(None) };
    let names: Vec<&Value> = options.iter().filter_map(|o| o["properties"][tag].get("const")).collect();
    let Some(map) = value.as_object() else { return Err(invalid(key, format!("must be a table, got {value}"))) };
    let Some(given) = map.get(tag) else {
        return Err(invalid(&child(key, tag), format!("required key is missing (one of {})", quoted(&names))));
    };
    match options.iter().find(|o| o["properties"][tag].get("const") == Some(given)) {
        Some(option) => Ok(Some(option)),
        None => Err(invalid(&child(key, tag), format!("must be one of {}, got {given}", quoted(&names)))),
    }
}

fn object(root: &Value, schema: &Value, variant: Option<&Value>, value: &Value, key: &str) -> Result<(), Invalid> {
    let Some(map) = value.as_object() else { return Err(invalid(key, format!("must be a table, got {value}"))) };
    let empty = Map::new();
    let scopes: Vec<&Value> = std::iter::once(schema).chain(variant).collect();
    let properties = |s: &Value| s.get("properties").and_then(Value::as_object).unwrap_or(&empty).clone();
    let declared: Map<String, Value> = scopes.iter().flat_map(|s| properties(s)).collect();
    for s in &scopes {
        for name in s.get("required").and_then(Value::as_array).into_iter().flatten().filter_map(Value::as_str) {
            if !map.contains_key(name) {
                return Err(invalid(&child(key, name), "required key is missing"));
            }
        }
    }
    for (name, item) in map {
        match declared.get(name) {
            Some(property) => walk(root, property, item, &child(key, name))?,
            None => return Err(invalid(&child(key, name), "unknown key")),
        }
    }
    Ok(())
}

fn array(root: &Value, schema: &Value, value: &Value, key: &str) -> Result<(), Invalid> {
    let Some(items) = value.as_array() else { return Err(invalid(key, format!("must be a list, got {value}"))) };
    let (min, max) = (schema.get("minItems").and_then(Value::as_u64), schema.get("maxItems").and_then(Value::as_u64));
    let n = items.len() as u64;
    match (min, max) {
        (Some(a), Some(b)) if a == b && n != a => return Err(invalid(key, format!("must have {a} items, got {n}"))),
        (Some(a), _) if n < a => return Err(invalid(key, format!("must have at least {a} items, got {n}"))),
        (_, Some(b)) if n > b => return Err(invalid(key, format!("must have at most {b} items, got {n}"))),
        _ => {}
    }
    if let Some(item) = schema.get("items") {
        for (i, v) in items.iter().enumerate() {
            walk(root, item, v, &format!("{key}[{i}]"))?;
        }
    }
    Ok(())
}

/// The bound keywords with the words that state them.
const BOUNDS: [(&str, &str); 4] = [
    ("exclusiveMinimum", "greater than"),
    ("minimum", "at least"),
    ("exclusiveMaximum", "less than"),
    ("maximum", "at most"),
];

fn within(name: &str, ordering: std::cmp::Ordering) -> bool {
    use std::cmp::Ordering::*;
    match name {
        "exclusiveMinimum" => ordering == Greater,
        "minimum" => ordering != Less,
        "exclusiveMaximum" => ordering == Less,
        _ => ordering != Greater,
    }
}

fn number(schema: &Value, value: &Value, key: &str) -> Result<(), Invalid> {
    let x = match value.as_f64() {
        Some(x) if x.is_finite() => x,
        _ => return Err(invalid(key, format!("must be a finite number, got {value}"))),
    };
    for (name, words) in BOUNDS {
        if let Some(bound) = schema.get(name).and_then(Value::as_f64) {
            if !x.partial_cmp(&bound).is_some_and(|o| within(name, o)) {
                return Err(invalid(key, format!("must be {words} {}, got {value}", schema[name])));
            }
        }
    }
    Ok(())
}

fn integer(schema: &Value, value: &Value, key: &str) -> Result<(), Invalid> {
    // Compared exactly, in 128 bits: a bound of 2⁶³ − 1 must refuse 2⁶³.
    let wide = |v: &Value| v.as_u64().map(i128::from).or_else(|| v.as_i64().map(i128::from));
    let Some(x) = wide(value) else { return Err(invalid(key, format!("must be a whole number, got {value}"))) };
    for (name, words) in BOUNDS {
        let ok = match schema.get(name) {
            None => true,
            Some(b) => match wide(b) {
                Some(bound) => within(name, x.cmp(&bound)),
                None => b.as_f64().is_none_or(|bound| (x as f64).partial_cmp(&bound).is_some_and(|o| within(name, o))),
            },
        };
        if !ok {
            return Err(invalid(key, format!("must be {words} {}, got {value}", schema[name])));
        }
    }
    Ok(())
}

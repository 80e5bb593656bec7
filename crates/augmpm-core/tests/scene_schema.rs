//! The scene schema: every key documented, with a unit and a range where it is a number, and scene
//! values checked against it with errors that name the dotted key.

use augmpm_core::Scene;
use serde_json::{json, Value};

/// Calls `visit(key, schema)` for every key of the scene schema, through `$ref`s, choices and lists.
fn each_key(root: &Value, schema: &Value, key: &str, visit: &mut dyn FnMut(&str, &Value)) {
    if let Some(r) = schema.get("$ref").and_then(Value::as_str) {
        let name = r.rsplit('/').next().unwrap();
        each_key(root, &root["$defs"][name], key, visit);
    }
    for options in ["oneOf", "anyOf"] {
        for option in schema.get(options).and_then(Value::as_array).into_iter().flatten() {
            each_key(root, option, key, visit);
        }
    }
    if let Some(items) = schema.get("items") {
        each_key(root, items, &format!("{key}[]"), visit);
    }
    for (name, property) in schema.get("properties").and_then(Value::as_object).into_iter().flatten() {
        let child = if key.is_empty() { name.clone() } else { format!("{key}.{name}") };
        visit(&child, property);
        each_key(root, property, &child, visit);
    }
}

/// Whether a key holds numbers: a number, an integer, or a list (of lists) of them.
fn numeric(schema: &Value) -> bool {
    let kinds: Vec<&str> = match &schema["type"] {
        Value::String(t) => vec![t.as_str()],
        Value::Array(ts) => ts.iter().filter_map(Value::as_str).collect(),
        _ => vec![],
    };
    kinds.iter().any(|k| *k == "number" || *k == "integer")
        || (kinds.contains(&"array") && numeric(&schema["items"]))
        || schema.get("anyOf").and_then(Value::as_array).is_some_and(|o| o.iter().any(numeric))
}

/// Whether a schema or its items (down to the numbers) state a bound.
fn bounded(schema: &Value) -> bool {
    ["minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"].iter().any(|b| schema.get(b).is_some())
        || schema.get("items").is_some_and(bounded)
        || schema.get("anyOf").and_then(Value::as_array).is_some_and(|o| o.iter().any(bounded))
}

/// Every key of 2D and 3D scenes has a one-line doc; every numeric key a unit and a range (bounds, or
/// `unbounded`: any finite value); a tag key (`type`, `shape`) is documented by its options.
#[test]
fn every_key_has_a_doc_a_unit_and_a_range() {
    for root in [Scene::schema(), augmpm_core::scene3::Scene3::schema()] {
        documented(root);
    }
}

fn documented(root: &Value) {
    let mut missing = Vec::new();
    let mut keys = 0;
    each_key(root, root, "", &mut |key, schema| {
        keys += 1;
        if schema.get("const").is_some() {
            return; // the tag of a choice: its options carry the docs
        }
        if schema.get("description").and_then(Value::as_str).is_none_or(str::is_empty) {
            missing.push(format!("{key}: no doc"));
        }
        if numeric(schema) {
            if schema.get("unit").and_then(Value::as_str).is_none() {
                missing.push(format!("{key}: no unit"));
            }
            if !bounded(schema) && schema.get("unbounded") != Some(&Value::Bool(true)) {
                missing.push(format!("{key}: no range"));
            }
        }
    });
    assert!(keys > 40, "only {keys} keys were visited");
    assert!(missing.is_empty(), "scene keys without a doc, a unit or a range:\n{}", missing.join("\n"));
}

/// Every option of a choice of names (`wall_condition`, `method`, ...) has a doc of its own.
#[test]
fn every_option_has_a_doc() {
    for root in [Scene::schema(), augmpm_core::scene3::Scene3::schema()] {
        for (name, def) in root["$defs"].as_object().unwrap() {
            for option in def.get("oneOf").and_then(Value::as_array).into_iter().flatten() {
                assert!(option.get("description").is_some(), "{name}: option {} has no doc", option["const"]);
            }
        }
    }
}

fn scene() -> Value {
    json!({
        "gravity": [0.0, -9.81],
        "grid": {"domain": [1.0, 1.0], "resolution": 16},
        "time": {"dt": 1e-4, "steps": 10, "output_interval": 5},
        "walls": [{"type": "circle", "center": [0.5, 0.5], "radius": 0.1}],
        "bodies": [{"shape": "box", "min": [0.1, 0.1], "max": [0.3, 0.3],
                    "material": {"type": "elastic", "density": 1000.0, "youngs_modulus": 1e4, "poisson_ratio": 0.3}}]
    })
}

/// The error of `scene()` changed at `pointer` to `value` (`None`: the key removed), as "key: reason".
fn error_with(pointer: &str, value: Option<Value>) -> String {
    let mut s = scene();
    let (parent, name) = pointer.rsplit_once('/').unwrap();
    let table = s.pointer_mut(parent).unwrap();
    match (value, table) {
        (Some(v), Value::Object(m)) => {
            m.insert(name.to_string(), v);
        }
        (Some(v), Value::Array(a)) => a[name.parse::<usize>().unwrap()] = v,
        (None, Value::Object(m)) => {
            m.remove(name);
        }
        _ => unreachable!(),
    }
    Scene::from_json(&s.to_string()).unwrap_err().to_string()
}

/// A bad value is refused naming its dotted key and the declared range.
#[test]
fn errors_name_the_dotted_key() {
    assert!(Scene::from_json(&scene().to_string()).is_ok());
    let cases = [
        (
            "/bodies/0/material/poisson_ratio",
            Some(json!(0.5)),
            "bodies[0].material.poisson_ratio: must be less than 0.5, got 0.5",
        ),
        (
            "/bodies/0/material/density",
            Some(json!(-1.0)),
            "bodies[0].material.density: must be greater than 0.0, got -1.0",
        ),
        (
            "/bodies/0/material/type",
            Some(json!("lava")),
            "bodies[0].material.type: must be one of \"fluid\", \"elastic\", \"stvk\", \"snow\", \"sand\", got \"lava\"",
        ),
        ("/bodies/0/material/stiffness", Some(json!(1.0)), "bodies[0].material.stiffness: unknown key"),
        ("/bodies/0/radius", Some(json!(1.0)), "bodies[0].radius: unknown key"),
        ("/bodies/0/min", Some(json!([0.1])), "bodies[0].min: must have 2 items, got 1"),
        ("/walls/0/radius", Some(json!(0.0)), "walls[0].radius: must be greater than 0.0, got 0.0"),
        ("/walls/0/side", Some(json!("left")), "walls[0].side: must be one of \"outside\", \"inside\", got \"left\""),
        ("/grid/resolution", Some(json!(1)), "grid.resolution: must be at least 2, got 1"),
        ("/grid/resolution", Some(json!(2.5)), "grid.resolution: must be a whole number, got 2.5"),
        ("/grid/domain", Some(json!([1.0, -1.0])), "grid.domain[1]: must be greater than 0.0, got -1.0"),
        (
            "/time/steps",
            Some(json!(9_223_372_036_854_775_808u64)),
            "time.steps: must be at most 9223372036854775807, got 9223372036854775808",
        ),
        ("/time/output_interval", None, "time.output_interval: required key is missing"),
        ("/time/cfl", Some(json!(0.5)), "time: give exactly one of dt and cfl"),
        ("/gravity", Some(json!("down")), "gravity: must be a list, got \"down\""),
        ("/method", Some(json!("clever")), "method: must be one of \"naive\", \"augmented\", got \"clever\""),
        ("/wall_friction", Some(json!(-0.5)), "wall_friction: must be at least 0.0, got -0.5"),
        ("/wall_friction", Some(json!("lots")), "wall_friction: must be \"inf\", got \"lots\""),
        (
            "/walls/0/friction",
            Some(json!(0.5)),
            "walls[0].friction: friction acts on separate walls; this wall is sticky",
        ),
        ("/bodies/0/max", Some(json!([0.05, 0.5])), "bodies[0].max: must exceed min along both axes"),
        (
            "/grid/domain",
            Some(json!([1.0, 0.55])),
            "grid.domain: height 0.55 is not a whole number (≥ 2) of cells of width 0.0625",
        ),
    ];
    for (pointer, value, expected) in cases {
        assert_eq!(error_with(pointer, value), expected, "at {pointer}");
    }
}

/// A scene built in code is checked as one read from a file: a NaN (null in JSON) is refused.
#[test]
fn scenes_built_in_code_are_checked_too() {
    let mut s: Scene = Scene::from_json(&scene().to_string()).unwrap();
    s.gravity[1] = f64::NAN as _;
    assert_eq!(s.validate().unwrap_err().to_string(), "gravity[1]: must be a finite number, got null");
    s.gravity[1] = -9.81;
    // An optional number is null in JSON when absent: a NaN or an infinity given there is refused too.
    s.time.dt = Some(f64::INFINITY as _);
    assert_eq!(s.validate().unwrap_err().to_string(), "time.dt: must be a finite number, got inf");
    s.time.dt = Some(1e-4);
    s.wall_friction = f64::NAN as _;
    assert!(s.validate().unwrap_err().to_string().starts_with("wall_friction: must be a number >= 0"));
    s.wall_friction = f64::INFINITY as _;
    assert!(s.validate().is_err(), "friction acts on separate walls only");
    s.wall_friction = 0.0;
    s.augmented.delta = 1.5;
    let err = s.build(augmpm_core::Method::Augmented).err().unwrap();
    assert_eq!(err.to_string(), "augmented.delta: must be less than 1.5, got 1.5");
}

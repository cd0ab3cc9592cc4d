//! A USD layer as data: the prims, properties and values one file holds (USD's Sdf data
//! model, restricted to what our layouts use). Built once per file by `usd` and serialized by
//! `usda` (text) and `usdc` (binary crate), so the two formats hold the same layer.
//!
//! Invariants (kept by the builders, checked by the writers where a file format needs them):
//! prim and property names are USD identifiers (namespaced with `:` for properties), unique
//! among their siblings; paths in relationships and connections name specs of the same layer.

/// One value of an attribute or of the layer's metadata, typed as USD types it.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    Token(String),
    String(String),
    /// An asset path, e.g. `./texture.png` (relative to the layer).
    Asset(String),
    Double(f64),
    Float(f32),
    Vec3f([f32; 3]),
    Tokens(Vec<String>),
    Ints(Vec<i32>),
    Floats(Vec<f32>),
    Vec2fs(Vec<[f32; 2]>),
    Vec3fs(Vec<[f32; 3]>),
}

/// An attribute: a default value, or time samples, or a connection, or only a declaration
/// (a shader output).
#[derive(Debug, Clone, PartialEq)]
pub struct Attribute {
    pub name: String,
    /// USD's value type name, e.g. `point3f[]`, `token`, `texCoord2f[]`.
    pub type_name: &'static str,
    /// `uniform` (no time samples) rather than varying.
    pub uniform: bool,
    pub default: Option<Value>,
    /// `(time code, value)`, times increasing.
    pub samples: Vec<(f64, Value)>,
    /// The path of the property this attribute reads (`.connect`).
    pub connection: Option<String>,
    /// Primvar `interpolation` metadata (`vertex`, `faceVarying`).
    pub interpolation: Option<&'static str>,
}

impl Attribute {
    /// A varying attribute with a default value.
    pub fn new(name: impl Into<String>, type_name: &'static str, value: Value) -> Attribute {
        Attribute { name: name.into(), type_name, uniform: false, default: Some(value), samples: Vec::new(), connection: None, interpolation: None }
    }

    /// A `uniform` attribute with a default value.
    pub fn uniform(name: impl Into<String>, type_name: &'static str, value: Value) -> Attribute {
        Attribute { uniform: true, ..Attribute::new(name, type_name, value) }
    }

    /// Declared, without a value (a shader output).
    pub fn declared(name: impl Into<String>, type_name: &'static str) -> Attribute {
        Attribute { default: None, ..Attribute::new(name, type_name, Value::Float(0.0)) }
    }

    /// Connected to the property at `path`.
    pub fn connected(name: impl Into<String>, type_name: &'static str, path: String) -> Attribute {
        Attribute { connection: Some(path), ..Attribute::declared(name, type_name) }
    }

    /// Sampled at `samples` (time code, value).
    pub fn sampled(name: impl Into<String>, type_name: &'static str, samples: Vec<(f64, Value)>) -> Attribute {
        Attribute { samples, ..Attribute::declared(name, type_name) }
    }

    pub fn with_interpolation(self, interpolation: &'static str) -> Attribute {
        Attribute { interpolation: Some(interpolation), ..self }
    }
}

/// A property of a prim, in the order it is written.
#[derive(Debug, Clone, PartialEq)]
pub enum Property {
    Attribute(Attribute),
    /// A relationship and the paths of its targets.
    Relationship { name: String, targets: Vec<String> },
}

impl Property {
    pub fn name(&self) -> &str {
        match self {
            Property::Attribute(a) => &a.name,
            Property::Relationship { name, .. } => name,
        }
    }
}

/// A `def` prim.
#[derive(Debug, Clone, PartialEq)]
pub struct Prim {
    pub name: String,
    pub type_name: &'static str,
    /// Prepended API schemas, e.g. `SkelBindingAPI`.
    pub api_schemas: Vec<&'static str>,
    pub properties: Vec<Property>,
    pub children: Vec<Prim>,
}

impl Prim {
    pub fn new(type_name: &'static str, name: impl Into<String>) -> Prim {
        Prim { name: name.into(), type_name, api_schemas: Vec::new(), properties: Vec::new(), children: Vec::new() }
    }

    pub fn with_api(mut self, schema: &'static str) -> Prim {
        self.api_schemas.push(schema);
        self
    }

    pub fn attribute(&mut self, a: Attribute) {
        self.properties.push(Property::Attribute(a));
    }

    pub fn relationship(&mut self, name: impl Into<String>, targets: Vec<String>) {
        self.properties.push(Property::Relationship { name: name.into(), targets });
    }
}

/// A layer: its metadata (`defaultPrim`, time codes, `upAxis`...) and its root prims.
#[derive(Debug, Clone, PartialEq)]
pub struct Layer {
    /// `(field, value)` in the order written; the text name is used (`doc` for USD's
    /// `documentation` field).
    pub metadata: Vec<(&'static str, Value)>,
    pub prims: Vec<Prim>,
}

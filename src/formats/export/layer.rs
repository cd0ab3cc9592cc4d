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
    /// A `token` (an identifier such as `rightHanded`).
    Token(String),
    /// A `string`.
    String(String),
    /// An asset path, e.g. `./texture.png` (relative to the layer).
    Asset(String),
    /// A `double`.
    Double(f64),
    /// A `float`.
    Float(f32),
    /// Three floats, e.g. a `color3f`.
    Vec3f([f32; 3]),
    /// A `token[]`.
    Tokens(Vec<String>),
    /// An `int[]`, e.g. face vertex counts or indices.
    Ints(Vec<i32>),
    /// A `float[]`.
    Floats(Vec<f32>),
    /// An array of float pairs, e.g. `texCoord2f[]`.
    Vec2fs(Vec<[f32; 2]>),
    /// An array of float triples, e.g. `point3f[]` or `normal3f[]`.
    Vec3fs(Vec<[f32; 3]>),
}

/// An attribute: a default value, or time samples, or a connection, or only a declaration
/// (a shader output).
#[derive(Debug, Clone, PartialEq)]
pub struct Attribute {
    /// The attribute's name, possibly namespaced (e.g. `primvars:st`).
    pub name: String,
    /// USD's value type name, e.g. `point3f[]`, `token`, `texCoord2f[]`.
    pub type_name: &'static str,
    /// `uniform` (no time samples) rather than varying.
    pub uniform: bool,
    /// The default (unsampled) value; `None` when declared, connected or sampled.
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

    /// The same attribute with primvar `interpolation` metadata (e.g. `faceVarying`).
    pub(crate) fn with_interpolation(self, interpolation: &'static str) -> Attribute {
        Attribute { interpolation: Some(interpolation), ..self }
    }
}

/// A property of a prim, in the order it is written.
#[derive(Debug, Clone, PartialEq)]
pub enum Property {
    /// An attribute.
    Attribute(Attribute),
    /// A relationship and the paths of its targets.
    Relationship {
        /// The relationship's name, possibly namespaced (e.g. `skel:skeleton`).
        name: String,
        /// Absolute paths of the target prims or properties.
        targets: Vec<String>,
    },
}

impl Property {
    /// The property's name.
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
    /// The prim's name, unique among its siblings.
    pub name: String,
    /// The schema type, e.g. `Mesh`, `Xform` or `Shader`.
    pub type_name: &'static str,
    /// Prepended API schemas, e.g. `SkelBindingAPI`.
    pub api_schemas: Vec<&'static str>,
    /// Properties, in the order written.
    pub properties: Vec<Property>,
    /// Child prims, in the order written.
    pub children: Vec<Prim>,
}

impl Prim {
    /// A prim of schema `type_name` without API schemas, properties or children.
    pub fn new(type_name: &'static str, name: impl Into<String>) -> Prim {
        Prim { name: name.into(), type_name, api_schemas: Vec::new(), properties: Vec::new(), children: Vec::new() }
    }

    /// The same prim with API schema `schema` added last.
    pub(crate) fn with_api(mut self, schema: &'static str) -> Prim {
        self.api_schemas.push(schema);
        self
    }

    /// Add an attribute after the existing properties.
    pub fn attribute(&mut self, a: Attribute) {
        self.properties.push(Property::Attribute(a));
    }

    /// Add a relationship to `targets` (paths) after the existing properties.
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
    /// The root prims, in the order written.
    pub prims: Vec<Prim>,
}

/// A valid USD prim name from an asset name: letters, digits and `_`, not starting with a digit.
pub fn prim_name(name: &str) -> String {
    let mut s: String = name.chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '_' }).collect();
    if !s.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_') {
        s.insert(0, '_');
    }
    s
}

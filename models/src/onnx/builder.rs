//! A small ONNX graph builder: named inputs, outputs, initializers and nodes, with
//! unique value names generated for intermediate results.

use super::proto::{
    AttributeProto, DimValue, Dimension, GraphProto, ModelProto, NodeProto, OperatorSetIdProto,
    StringStringEntryProto, TensorProto, TensorShapeProto, TypeProto, TypeProtoTensor,
    ValueInfoProto, attribute_type, data_type,
};
use std::collections::HashSet;

/// The ONNX IR version frugal writes (IR 8 goes with opsets up to 18 and is read by
/// every ONNX Runtime since 1.14).
pub const IR_VERSION: i64 = 8;

/// The default-domain opset frugal targets.
pub const OPSET: i64 = 17;

/// One dimension of a graph input or output: fixed, or a named symbolic size.
#[derive(Clone, Debug, PartialEq)]
pub enum Dim {
    /// A fixed size.
    Fixed(i64),
    /// A symbolic size, e.g. `"rois"`.
    Named(&'static str),
}

impl From<i64> for Dim {
    fn from(v: i64) -> Self {
        Dim::Fixed(v)
    }
}

/// An attribute of a node.
pub fn attr_int(name: &str, value: i64) -> AttributeProto {
    AttributeProto {
        name: name.into(),
        i: value,
        r#type: attribute_type::INT,
        ..Default::default()
    }
}

/// An attribute holding a list of integers.
pub fn attr_ints(name: &str, values: &[i64]) -> AttributeProto {
    AttributeProto {
        name: name.into(),
        ints: values.to_vec(),
        r#type: attribute_type::INTS,
        ..Default::default()
    }
}

/// An attribute holding one float.
pub fn attr_float(name: &str, value: f32) -> AttributeProto {
    AttributeProto {
        name: name.into(),
        f: value,
        r#type: attribute_type::FLOAT,
        ..Default::default()
    }
}

/// An attribute holding a string.
pub fn attr_string(name: &str, value: &str) -> AttributeProto {
    AttributeProto {
        name: name.into(),
        s: value.as_bytes().to_vec(),
        r#type: attribute_type::STRING,
        ..Default::default()
    }
}

fn value_info(name: &str, elem_type: i32, dims: &[Dim]) -> ValueInfoProto {
    let dim = dims
        .iter()
        .map(|d| Dimension {
            value: Some(match d {
                Dim::Fixed(v) => DimValue::Value(*v),
                Dim::Named(n) => DimValue::Param((*n).to_string()),
            }),
        })
        .collect();
    ValueInfoProto {
        name: name.into(),
        r#type: Some(TypeProto {
            tensor_type: Some(TypeProtoTensor {
                elem_type,
                shape: Some(TensorShapeProto { dim }),
            }),
        }),
    }
}

/// Builds one ONNX graph.
#[derive(Debug, Default)]
pub struct GraphBuilder {
    name: String,
    nodes: Vec<NodeProto>,
    initializers: Vec<TensorProto>,
    inputs: Vec<ValueInfoProto>,
    outputs: Vec<ValueInfoProto>,
    names: HashSet<String>,
}

impl GraphBuilder {
    /// An empty graph called `name`.
    pub fn new(name: &str) -> Self {
        Self {
            name: name.into(),
            ..Self::default()
        }
    }

    /// A fresh value name starting with `stem`.
    fn fresh(&mut self, stem: &str) -> String {
        if self.names.insert(stem.to_string()) {
            return stem.to_string();
        }
        (1..)
            .map(|i| format!("{stem}_{i}"))
            .find(|n| !self.names.contains(n))
            .inspect(|n| {
                self.names.insert(n.clone());
            })
            .unwrap_or_default()
    }

    /// Declare a float graph input; returns its name.
    pub fn input(&mut self, name: &str, dims: &[Dim]) -> String {
        self.input_typed(name, data_type::FLOAT, dims)
    }

    /// Declare a graph input of element type `elem_type` (one of [`data_type`]).
    pub fn input_typed(&mut self, name: &str, elem_type: i32, dims: &[Dim]) -> String {
        let name = self.fresh(name);
        self.inputs.push(value_info(&name, elem_type, dims));
        name
    }

    /// Declare an existing value as a graph output of element type `elem_type`
    /// (one of [`data_type`]).
    pub fn output(&mut self, value: &str, elem_type: i32, dims: &[Dim]) {
        self.outputs.push(value_info(value, elem_type, dims));
    }

    fn initializer(&mut self, name: &str, data_type: i32, dims: &[i64], raw: Vec<u8>) -> String {
        let name = self.fresh(name);
        self.initializers.push(TensorProto {
            dims: dims.to_vec(),
            data_type,
            name: name.clone(),
            raw_data: raw,
        });
        name
    }

    /// A float32 constant (a graph initializer); returns its name.
    pub fn constant_f32(&mut self, name: &str, dims: &[i64], values: &[f32]) -> String {
        let raw = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.initializer(name, data_type::FLOAT, dims, raw)
    }

    /// An int64 constant; returns its name.
    pub fn constant_i64(&mut self, name: &str, dims: &[i64], values: &[i64]) -> String {
        let raw = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.initializer(name, data_type::INT64, dims, raw)
    }

    /// An int32 constant; returns its name.
    pub fn constant_i32(&mut self, name: &str, dims: &[i64], values: &[i32]) -> String {
        let raw = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.initializer(name, data_type::INT32, dims, raw)
    }

    /// An int8 constant; returns its name.
    pub fn constant_i8(&mut self, name: &str, dims: &[i64], values: &[i8]) -> String {
        let raw = values.iter().map(|v| v.to_le_bytes()[0]).collect();
        self.initializer(name, data_type::INT8, dims, raw)
    }

    /// A uint8 constant; returns its name.
    pub fn constant_u8(&mut self, name: &str, dims: &[i64], values: &[u8]) -> String {
        self.initializer(name, data_type::UINT8, dims, values.to_vec())
    }

    /// Add a node with `outputs` results named after `name`; returns the result names.
    pub fn node_n(
        &mut self,
        op_type: &str,
        name: &str,
        inputs: &[&str],
        attributes: Vec<AttributeProto>,
        outputs: usize,
    ) -> Vec<String> {
        let node_name = self.fresh(&format!("{name}/{op_type}"));
        let results: Vec<String> = (0..outputs)
            .map(|i| {
                if outputs == 1 {
                    self.fresh(name)
                } else {
                    self.fresh(&format!("{name}:{i}"))
                }
            })
            .collect();
        self.nodes.push(NodeProto {
            input: inputs.iter().map(|s| (*s).to_string()).collect(),
            output: results.clone(),
            name: node_name,
            op_type: op_type.into(),
            attribute: attributes,
            domain: String::new(),
        });
        results
    }

    /// Add a single-output node; returns the result's name.
    pub fn node(
        &mut self,
        op_type: &str,
        name: &str,
        inputs: &[&str],
        attributes: Vec<AttributeProto>,
    ) -> String {
        self.node_n(op_type, name, inputs, attributes, 1)
            .pop()
            .unwrap_or_default()
    }

    /// Finish the graph into a model for [`OPSET`], with `metadata` as key/value pairs.
    pub fn finish(self, doc: &str, metadata: &[(&str, String)]) -> ModelProto {
        ModelProto {
            ir_version: IR_VERSION,
            producer_name: "frugal".into(),
            producer_version: env!("CARGO_PKG_VERSION").into(),
            doc_string: doc.into(),
            graph: Some(GraphProto {
                node: self.nodes,
                name: self.name,
                initializer: self.initializers,
                input: self.inputs,
                output: self.outputs,
            }),
            opset_import: vec![OperatorSetIdProto {
                domain: String::new(),
                version: OPSET,
            }],
            metadata_props: metadata
                .iter()
                .map(|(k, v)| StringStringEntryProto {
                    key: (*k).into(),
                    value: v.clone(),
                })
                .collect(),
        }
    }
}

//! A small ONNX graph builder: nodes with one output named after the node, constant and
//! weight initializers, and typed inputs and outputs. Node and initializer names are the
//! checkpoint's weight paths (`mlp.body.3.fc1`), so a name reads the same in a checkpoint, a
//! graph and a profile.

use crate::onnx::{
    AttributeProto, AttributeType, DataType, GraphProto, NodeProto, TensorProto, TensorShapeProto,
    TypeProto, ValueInfoProto, tensor_shape_proto, type_proto,
};

/// One dimension of a graph input or output.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Dim {
    /// A fixed size.
    Fixed(usize),
    /// A size named by a symbol, chosen by the caller at run time.
    Symbolic(String),
}

/// How weight initializers are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum WeightType {
    /// f32, as trained.
    #[default]
    F32,
    /// f16 (half the file size), cast back to f32 in the graph.
    F16,
}

/// An integer attribute.
pub fn attr_int(name: &str, v: i64) -> AttributeProto {
    AttributeProto {
        name: Some(name.to_string()),
        r#type: Some(AttributeType::Int as i32),
        i: Some(v),
        ..Default::default()
    }
}

/// A float attribute.
pub fn attr_float(name: &str, v: f32) -> AttributeProto {
    AttributeProto {
        name: Some(name.to_string()),
        r#type: Some(AttributeType::Float as i32),
        f: Some(v),
        ..Default::default()
    }
}

/// An integer-list attribute.
pub fn attr_ints(name: &str, v: &[i64]) -> AttributeProto {
    AttributeProto {
        name: Some(name.to_string()),
        r#type: Some(AttributeType::Ints as i32),
        ints: v.to_vec(),
        ..Default::default()
    }
}

/// A tensor initializer holding `data` as little-endian `raw_data`.
pub fn tensor_f32(name: &str, dims: &[usize], data: &[f32]) -> TensorProto {
    TensorProto {
        name: Some(name.to_string()),
        dims: dims.iter().map(|&d| d as i64).collect(),
        data_type: Some(DataType::Float as i32),
        raw_data: Some(data.iter().flat_map(|v| v.to_le_bytes()).collect()),
        ..Default::default()
    }
}

/// An f16 tensor initializer holding `data` rounded to half precision.
pub fn tensor_f16(name: &str, dims: &[usize], data: &[f32]) -> TensorProto {
    TensorProto {
        name: Some(name.to_string()),
        dims: dims.iter().map(|&d| d as i64).collect(),
        data_type: Some(DataType::Float16 as i32),
        raw_data: Some(
            data.iter()
                .flat_map(|&v| half::f16::from_f32(v).to_le_bytes())
                .collect(),
        ),
        ..Default::default()
    }
}

/// An i64 tensor initializer.
pub fn tensor_i64(name: &str, dims: &[usize], data: &[i64]) -> TensorProto {
    TensorProto {
        name: Some(name.to_string()),
        dims: dims.iter().map(|&d| d as i64).collect(),
        data_type: Some(DataType::Int64 as i32),
        raw_data: Some(data.iter().flat_map(|v| v.to_le_bytes()).collect()),
        ..Default::default()
    }
}

/// A typed value declaration (graph input or output).
pub fn value_info(name: &str, elem: DataType, dims: &[Dim]) -> ValueInfoProto {
    let dim = dims
        .iter()
        .map(|d| tensor_shape_proto::Dimension {
            denotation: None,
            value: Some(match d {
                Dim::Fixed(n) => tensor_shape_proto::dimension::Value::DimValue(*n as i64),
                Dim::Symbolic(s) => tensor_shape_proto::dimension::Value::DimParam(s.clone()),
            }),
        })
        .collect();
    ValueInfoProto {
        name: Some(name.to_string()),
        r#type: Some(TypeProto {
            denotation: None,
            value: Some(type_proto::Value::TensorType(type_proto::Tensor {
                elem_type: Some(elem as i32),
                shape: Some(TensorShapeProto { dim }),
            })),
        }),
        doc_string: None,
    }
}

/// Collects the nodes, initializers, inputs and outputs of one graph.
#[derive(Debug, Default)]
pub struct GraphBuilder {
    weights: WeightType,
    nodes: Vec<NodeProto>,
    initializers: Vec<TensorProto>,
    inputs: Vec<ValueInfoProto>,
    outputs: Vec<ValueInfoProto>,
}

impl GraphBuilder {
    /// An empty graph whose weights are stored as `weights`.
    pub fn new(weights: WeightType) -> GraphBuilder {
        GraphBuilder {
            weights,
            ..Default::default()
        }
    }

    /// Declares a graph input; returns its name.
    pub fn input(&mut self, name: &str, elem: DataType, dims: &[Dim]) -> String {
        self.inputs.push(value_info(name, elem, dims));
        name.to_string()
    }

    /// Declares a graph output (a value some node produces).
    pub fn output(&mut self, name: &str, elem: DataType, dims: &[Dim]) {
        self.outputs.push(value_info(name, elem, dims));
    }

    /// An f32 constant, always stored in f32 (sample positions, frequencies, limits);
    /// returns its name.
    pub fn constant_f32(&mut self, name: &str, dims: &[usize], data: &[f32]) -> String {
        self.initializers.push(tensor_f32(name, dims, data));
        name.to_string()
    }

    /// An i64 constant (shapes, axes, slice bounds); returns its name.
    pub fn constant_i64(&mut self, name: &str, dims: &[usize], data: &[i64]) -> String {
        self.initializers.push(tensor_i64(name, dims, data));
        name.to_string()
    }

    /// A trained weight, stored as the builder's [`WeightType`]; returns the name of its
    /// f32 value (the initializer itself, or a `Cast` of it named `{name}.f32`).
    pub fn weight(&mut self, name: &str, dims: &[usize], data: &[f32]) -> String {
        match self.weights {
            WeightType::F32 => self.constant_f32(name, dims, data),
            WeightType::F16 => {
                self.initializers.push(tensor_f16(name, dims, data));
                self.node(
                    "Cast",
                    &format!("{name}.f32"),
                    &[name],
                    vec![attr_int("to", DataType::Float as i64)],
                )
            }
        }
    }

    /// Appends a node `name` applying `op` to `inputs`; its one output is also called `name`,
    /// which is returned. Nodes must be added in topological order.
    pub fn node(
        &mut self,
        op: &str,
        name: &str,
        inputs: &[&str],
        attributes: Vec<AttributeProto>,
    ) -> String {
        self.nodes.push(NodeProto {
            input: inputs.iter().map(|s| s.to_string()).collect(),
            output: vec![name.to_string()],
            name: Some(name.to_string()),
            op_type: Some(op.to_string()),
            domain: Some(String::new()),
            attribute: attributes,
            doc_string: None,
        });
        name.to_string()
    }

    /// Number of weight values stored so far.
    pub fn n_initializer_values(&self) -> usize {
        self.initializers
            .iter()
            .map(|t| t.dims.iter().product::<i64>().max(0) as usize)
            .sum()
    }

    /// The finished graph.
    pub fn finish(self, name: &str, doc: &str) -> GraphProto {
        GraphProto {
            node: self.nodes,
            name: Some(name.to_string()),
            initializer: self.initializers,
            doc_string: Some(doc.to_string()),
            input: self.inputs,
            output: self.outputs,
            value_info: Vec::new(),
        }
    }
}

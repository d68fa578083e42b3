//! A small ONNX graph builder: nodes with one output named after the node, constant and
//! weight initializers, and typed inputs and outputs. Node and initializer names are the
//! checkpoint's weight paths (`mlp.body.3.fc1`), so a name reads the same in a checkpoint, a
//! graph and a profile.

use nldf_model::contract::INT8_WEIGHT_MAX;
use nldf_model::onnx::{
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

/// The range of values entering each int8 product, by product name (`mlp.body.3.fc1`),
/// measured by running the f32 model on calibration rays; and the products kept in f32
/// ([`ActivationRanges::keep_f32`]), whose ranges go unused.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ActivationRanges {
    ranges: std::collections::BTreeMap<String, (f32, f32)>,
    f32_products: std::collections::BTreeSet<String>,
}

impl ActivationRanges {
    /// Widens `product`'s range to hold the finite `values`.
    pub fn observe(&mut self, product: &str, values: &[f32]) {
        let (lo, hi) = values
            .iter()
            .filter(|v| v.is_finite())
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            });
        if lo > hi {
            return;
        }
        let r = self
            .ranges
            .entry(product.to_string())
            .or_insert((f32::INFINITY, f32::NEG_INFINITY));
        *r = (r.0.min(lo), r.1.max(hi));
    }

    /// `product`'s range, once observed.
    pub fn get(&self, product: &str) -> Option<(f32, f32)> {
        self.ranges.get(product).copied()
    }

    /// Every product's range, by name.
    pub fn iter(&self) -> impl Iterator<Item = (&str, (f32, f32))> {
        self.ranges.iter().map(|(k, v)| (k.as_str(), *v))
    }

    /// Keeps `product` in f32 under [`WeightType::Int8`]: mixed precision, for the
    /// products whose int8 error costs the most (`nldf export --int8-f32`).
    pub fn keep_f32(&mut self, product: &str) {
        self.f32_products.insert(product.to_string());
    }

    /// Whether `product` stays in f32 ([`ActivationRanges::keep_f32`]).
    pub fn keeps_f32(&self, product: &str) -> bool {
        self.f32_products.contains(product)
    }
}

/// A product done in int8 under [`WeightType::Int8`] and the tensor it reads.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Tap {
    /// The product's name, the checkpoint's layer path (`mlp.body.3.fc1`).
    pub product: String,
    /// The f32 tensor it reads, `[n_rays, width]`.
    pub tensor: String,
    /// Its feature width.
    pub width: usize,
}

/// How weight initializers are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum WeightType {
    /// f32, as trained.
    #[default]
    F32,
    /// f16 (half the file size), cast back to f32 in the graph.
    F16,
    /// int8 for the products every ray passes through (the student's input and hidden
    /// layers: symmetric, one scale per output channel), with the activations quantized
    /// to uint8 over ranges calibrated on training rays (`QuantizeLinear`, then
    /// `MatMulInteger`); every other weight in f32. About a quarter of the file size.
    Int8,
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

/// A string attribute.
pub fn attr_string(name: &str, v: &str) -> AttributeProto {
    AttributeProto {
        name: Some(name.to_string()),
        r#type: Some(AttributeType::String as i32),
        s: Some(v.as_bytes().to_vec()),
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

/// An int8 tensor initializer.
pub fn tensor_i8(name: &str, dims: &[usize], data: &[i8]) -> TensorProto {
    TensorProto {
        name: Some(name.to_string()),
        dims: dims.iter().map(|&d| d as i64).collect(),
        data_type: Some(DataType::Int8 as i32),
        raw_data: Some(data.iter().map(|&v| v as u8).collect()),
        ..Default::default()
    }
}

/// Symmetric quantization of a weight matrix `w` `[out, in]` to integers in
/// `[-INT8_WEIGHT_MAX, INT8_WEIGHT_MAX]`, one scale per output channel:
/// `s_o = max_i |w_oi| / INT8_WEIGHT_MAX`, `q_oi = round(w_oi / s_o)` (a row of zeros gets
/// scale 1). Returns `q` transposed to `[in, out]`, the layout of `MatMulInteger`'s second
/// input, and the `out` scales.
pub fn quantize_per_channel(w: &[f32], out_dim: usize, in_dim: usize) -> (Vec<i8>, Vec<f32>) {
    let q_max = INT8_WEIGHT_MAX as f32;
    let scales: Vec<f32> = w
        .chunks_exact(in_dim)
        .map(|row| {
            let largest = row.iter().fold(0f32, |m, v| m.max(v.abs()));
            if largest > 0.0 { largest / q_max } else { 1.0 }
        })
        .collect();
    let mut q = vec![0i8; in_dim * out_dim];
    for (o, (row, &s)) in w.chunks_exact(in_dim).zip(&scales).enumerate() {
        for (i, &v) in row.iter().enumerate() {
            q[i * out_dim + o] = (v / s).round().clamp(-q_max, q_max) as i8;
        }
    }
    (q, scales)
}

/// A uint8 tensor initializer.
pub fn tensor_u8(name: &str, dims: &[usize], data: &[u8]) -> TensorProto {
    TensorProto {
        name: Some(name.to_string()),
        dims: dims.iter().map(|&d| d as i64).collect(),
        data_type: Some(DataType::Uint8 as i32),
        raw_data: Some(data.to_vec()),
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
    /// Calibrated input ranges of the int8 products, by product name.
    ranges: ActivationRanges,
    /// Products and the tensors they read ([`GraphBuilder::tap`]).
    taps: Vec<Tap>,
    nodes: Vec<NodeProto>,
    initializers: Vec<TensorProto>,
    inputs: Vec<ValueInfoProto>,
    outputs: Vec<ValueInfoProto>,
}

impl GraphBuilder {
    /// An empty graph whose weights are stored as `weights` (for
    /// [`WeightType::Int8`] see [`GraphBuilder::int8`]).
    pub fn new(weights: WeightType) -> GraphBuilder {
        GraphBuilder {
            weights,
            ..Default::default()
        }
    }

    /// An empty graph with int8 products whose inputs have the calibrated `ranges`.
    pub fn int8(ranges: ActivationRanges) -> GraphBuilder {
        GraphBuilder {
            weights: WeightType::Int8,
            ranges,
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

    /// A u8 constant (an 8-bit image); returns its name.
    pub fn constant_u8(&mut self, name: &str, dims: &[usize], data: &[u8]) -> String {
        self.initializers.push(tensor_u8(name, dims, data));
        name.to_string()
    }

    /// How the builder stores weights.
    pub fn weight_type(&self) -> WeightType {
        self.weights
    }

    /// A trained weight, stored as the builder's [`WeightType`] (in f32 under
    /// [`WeightType::Int8`], which quantizes only [`GraphBuilder::matmul_int8`]'s
    /// matrices); returns the name of its f32 value (the initializer itself, or a `Cast`
    /// of it named `{name}.f32`).
    pub fn weight(&mut self, name: &str, dims: &[usize], data: &[f32]) -> String {
        match self.weights {
            WeightType::F32 | WeightType::Int8 => self.constant_f32(name, dims, data),
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

    /// Records that the product `product` reads the tensor `x`: under
    /// [`WeightType::Int8`] these are the products done in integers, and
    /// [`GraphBuilder::taps`] lists them so that a calibration run can measure their
    /// inputs' ranges.
    pub fn tap(&mut self, product: &str, x: &str, width: usize) {
        self.taps.push(Tap {
            product: product.to_string(),
            tensor: x.to_string(),
            width,
        });
    }

    /// The products recorded by [`GraphBuilder::tap`], in graph order.
    pub fn taps(&self) -> &[Tap] {
        &self.taps
    }

    /// Whether the product `name` is done in int8: under [`WeightType::Int8`], unless its
    /// ranges keep it in f32 ([`ActivationRanges::keep_f32`]).
    pub fn int8_product(&self, name: &str) -> bool {
        self.weights == WeightType::Int8 && !self.ranges.keeps_f32(name)
    }

    /// `x W^T` in int8 with the activations' calibrated range, for `x` `[n, in]` and the
    /// f32 weight `w` `[out, in]` stored as `{name}.weight_q` `[in, out]`
    /// ([`quantize_per_channel`]). The range `[lo, hi]` of `x` measured on calibration
    /// rays ([`ActivationRanges`]), widened to hold 0, gives the uint8 step
    /// `s_x = (hi - lo) / 255` and zero point `z_x = round(-lo / s_x)`; then
    /// `x_q = QuantizeLinear(x, s_x, z_x)` and
    /// `Cast(MatMulInteger(x_q, W_q, z_x)) * (s_x s_w)`, the per-channel products' scales
    /// folded into one constant. Every ray's result depends on that ray alone, whatever
    /// shares its batch (a range measured per call would not). Returns the name of the f32
    /// product `[n, out]`, bias not added.
    pub fn matmul_int8(
        &mut self,
        name: &str,
        x: &str,
        w: &[f32],
        out_dim: usize,
        in_dim: usize,
    ) -> Result<String, String> {
        let (lo, hi) = self
            .ranges
            .get(name)
            .ok_or_else(|| format!("no calibrated activation range for `{name}`"))?;
        let (lo, hi) = (lo.min(0.0), hi.max(0.0));
        let step = if hi > lo { (hi - lo) / 255.0 } else { 1.0 };
        if !(step.is_finite() && step > 0.0) {
            return Err(format!(
                "`{name}`: activation range [{lo}, {hi}] is not finite"
            ));
        }
        let zero = (-lo / step).round().clamp(0.0, 255.0) as u8;
        let (q, scales) = quantize_per_channel(w, out_dim, in_dim);
        let w_q = format!("{name}.weight_q");
        self.initializers
            .push(tensor_i8(&w_q, &[in_dim, out_dim], &q));
        let combined: Vec<f32> = scales.iter().map(|s| s * step).collect();
        let combined = self.constant_f32(&format!("{name}.scale"), &[out_dim], &combined);
        let x_step = self.constant_f32(&format!("{name}.x_step"), &[], &[step]);
        let x_zero = format!("{name}.x_zero");
        self.initializers.push(tensor_u8(&x_zero, &[], &[zero]));
        let x_q = self.node(
            "QuantizeLinear",
            &format!("{name}.x_q"),
            &[x, &x_step, &x_zero],
            vec![],
        );
        let acc = self.node(
            "MatMulInteger",
            &format!("{name}.int32"),
            &[&x_q, &w_q, &x_zero],
            vec![],
        );
        let acc = self.node(
            "Cast",
            &format!("{name}.int32_f32"),
            &[&acc],
            vec![attr_int("to", DataType::Float as i64)],
        );
        Ok(self.node(
            "Mul",
            &format!("{name}.product"),
            &[&acc, &combined],
            vec![],
        ))
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

    /// Renames the value `old` to `new` wherever a node makes or reads it (so that a graph
    /// output can be made from it under the old name).
    pub fn rename(&mut self, old: &str, new: &str) {
        for n in &mut self.nodes {
            for v in n.input.iter_mut().chain(n.output.iter_mut()) {
                if v == old {
                    *v = new.to_string();
                }
            }
            if n.name.as_deref() == Some(old) {
                n.name = Some(new.to_string());
            }
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use nldf_model::contract::int8_pair_sum_max;

    #[test]
    fn no_pair_of_u8_by_s8_products_can_saturate_16_bits() {
        assert!(int8_pair_sum_max() <= i16::MAX as i32);
        // Whatever the weights, each quantized one is within 7 bits, so any two products
        // with uint8 activations sum within 16 bits.
        let w: Vec<f32> = (0..64).map(|k| (k as f32 - 31.5) * 1e3).collect();
        let (q, _) = quantize_per_channel(&w, 2, 32);
        let largest = q.iter().map(|v| v.unsigned_abs()).max().unwrap();
        assert_eq!(largest, INT8_WEIGHT_MAX as u8);
        assert!(2 * 255 * largest as i32 <= i16::MAX as i32);
    }

    #[test]
    fn per_channel_quantization_rounds_each_row_within_half_its_step() {
        // Rows of very different magnitudes, one of zeros; [out = 3, in = 4].
        let w = [
            0.5, -1.0, 0.25, 0.0, 1e-3, 2e-3, -4e-3, 0.0, 0.0, 0.0, 0.0, 0.0,
        ];
        let (q, scales) = quantize_per_channel(&w, 3, 4);
        assert_eq!(scales, [1.0 / 63.0, 4e-3 / 63.0, 1.0]);
        for o in 0..3 {
            let row_max = (0..4).map(|i| q[i * 3 + o].unsigned_abs()).max().unwrap();
            // Each non-zero row uses the whole 7-bit range.
            assert_eq!(row_max, if o == 2 { 0 } else { 63 });
            for i in 0..4 {
                let back = q[i * 3 + o] as f32 * scales[o];
                assert!((back - w[o * 4 + i]).abs() <= 0.5 * scales[o] * (1.0 + 1e-6));
            }
        }
    }

    #[test]
    fn activation_ranges_grow_over_finite_values_only() {
        let mut r = ActivationRanges::default();
        r.observe("a", &[0.5, f32::NAN, 2.0]);
        r.observe("a", &[-1.0, f32::INFINITY]);
        r.observe("b", &[f32::NAN]);
        assert_eq!(r.get("a"), Some((-1.0, 2.0)));
        assert_eq!(r.get("b"), None);
    }
}

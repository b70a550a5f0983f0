//! The part of the ONNX protobuf schema (`onnx/onnx.proto`, IR version 3 and later) that the SDK reads itself:
//! the model's metadata, the graph's inputs, outputs, nodes and initialisers. Decoded with `prost` from the
//! field numbers of the schema; every other field of a file is skipped, as protobuf readers do.
//!
//! This is what the native CPU engine and the GPU path read a file with ([`super::graph`]), and what the
//! contract and metadata checks read, with or without the `tract` feature: the reading of a model never
//! depends on which engine runs it.

use prost::Message;

/// ONNX `TensorProto.DataType.FLOAT`.
pub(crate) const FLOAT: i32 = 1;

/// Decodes the bytes of an ONNX file. Errors: the protobuf decoder's message (truncated or not a protobuf).
pub(crate) fn decode_model(bytes: &[u8]) -> Result<ModelProto, String> {
    ModelProto::decode(bytes).map_err(|e| e.to_string())
}

/// `ModelProto`: the file.
#[derive(Clone, PartialEq, Message)]
pub struct ModelProto {
    /// `ir_version` (1).
    #[prost(int64, tag = "1")]
    pub ir_version: i64,
    /// `graph` (7).
    #[prost(message, optional, tag = "7")]
    pub graph: Option<GraphProto>,
    /// `opset_import` (8): the operator set versions (kept so that a re-encoded model stays runnable).
    #[prost(message, repeated, tag = "8")]
    pub opset_import: Vec<OperatorSetIdProto>,
    /// `metadata_props` (14): the `tensorholo.*` keys.
    #[prost(message, repeated, tag = "14")]
    pub metadata_props: Vec<StringStringEntryProto>,
}

/// `OperatorSetIdProto`: one operator set and its version.
#[derive(Clone, PartialEq, Message)]
pub struct OperatorSetIdProto {
    /// `domain` (1): `""` for the default ONNX operators.
    #[prost(string, tag = "1")]
    pub domain: String,
    /// `version` (2).
    #[prost(int64, tag = "2")]
    pub version: i64,
}

/// `StringStringEntryProto`: one metadata key and value.
#[derive(Clone, PartialEq, Message)]
pub struct StringStringEntryProto {
    /// `key` (1).
    #[prost(string, tag = "1")]
    pub key: String,
    /// `value` (2).
    #[prost(string, tag = "2")]
    pub value: String,
}

/// `GraphProto`: nodes in topological order, weights, inputs and outputs.
#[derive(Clone, PartialEq, Message)]
pub struct GraphProto {
    /// `node` (1).
    #[prost(message, repeated, tag = "1")]
    pub node: Vec<NodeProto>,
    /// `name` (2).
    #[prost(string, tag = "2")]
    pub name: String,
    /// `initializer` (5): the weights.
    #[prost(message, repeated, tag = "5")]
    pub initializer: Vec<TensorProto>,
    /// `input` (11), initialisers included in older files.
    #[prost(message, repeated, tag = "11")]
    pub input: Vec<ValueInfoProto>,
    /// `output` (12).
    #[prost(message, repeated, tag = "12")]
    pub output: Vec<ValueInfoProto>,
}

/// `NodeProto`: one operator.
#[derive(Clone, PartialEq, Message)]
pub struct NodeProto {
    /// `input` (1): value names.
    #[prost(string, repeated, tag = "1")]
    pub input: Vec<String>,
    /// `output` (2): value names.
    #[prost(string, repeated, tag = "2")]
    pub output: Vec<String>,
    /// `name` (3).
    #[prost(string, tag = "3")]
    pub name: String,
    /// `op_type` (4), e.g. `Conv`.
    #[prost(string, tag = "4")]
    pub op_type: String,
    /// `attribute` (5).
    #[prost(message, repeated, tag = "5")]
    pub attribute: Vec<AttributeProto>,
    /// `domain` (7); empty for the default ONNX domain.
    #[prost(string, tag = "7")]
    pub domain: String,
}

/// `AttributeProto`: one attribute of a node (only the fields the CNN pattern uses).
#[derive(Clone, PartialEq, Message)]
pub struct AttributeProto {
    /// `name` (1).
    #[prost(string, tag = "1")]
    pub name: String,
    /// `f` (2).
    #[prost(float, tag = "2")]
    pub f: f32,
    /// `i` (3).
    #[prost(int64, tag = "3")]
    pub i: i64,
    /// `s` (4).
    #[prost(bytes = "vec", tag = "4")]
    pub s: Vec<u8>,
    /// `t` (5): a tensor (the value of a `Constant`).
    #[prost(message, optional, tag = "5")]
    pub t: Option<TensorProto>,
    /// `floats` (7).
    #[prost(float, repeated, tag = "7")]
    pub floats: Vec<f32>,
    /// `ints` (8).
    #[prost(int64, repeated, tag = "8")]
    pub ints: Vec<i64>,
    /// `type` (20), `AttributeProto.AttributeType`.
    #[prost(int32, tag = "20")]
    pub r#type: i32,
}

/// `TensorProto`: a constant tensor, its values in one of the typed fields or little-endian in `raw_data`.
#[derive(Clone, PartialEq, Message)]
pub struct TensorProto {
    /// `dims` (1).
    #[prost(int64, repeated, tag = "1")]
    pub dims: Vec<i64>,
    /// `data_type` (2), `TensorProto.DataType` (1 float, 2 uint8, 3 int8, 6 int32, 7 int64).
    #[prost(int32, tag = "2")]
    pub data_type: i32,
    /// `float_data` (4).
    #[prost(float, repeated, tag = "4")]
    pub float_data: Vec<f32>,
    /// `int32_data` (5), also holding 8- and 16-bit integers.
    #[prost(int32, repeated, tag = "5")]
    pub int32_data: Vec<i32>,
    /// `int64_data` (7).
    #[prost(int64, repeated, tag = "7")]
    pub int64_data: Vec<i64>,
    /// `name` (8).
    #[prost(string, tag = "8")]
    pub name: String,
    /// `raw_data` (9).
    #[prost(bytes = "vec", tag = "9")]
    pub raw_data: Vec<u8>,
}

/// `ValueInfoProto`: a graph input or output.
#[derive(Clone, PartialEq, Message)]
pub struct ValueInfoProto {
    /// `name` (1).
    #[prost(string, tag = "1")]
    pub name: String,
    /// `type` (2).
    #[prost(message, optional, tag = "2")]
    pub r#type: Option<TypeProto>,
}

/// `TypeProto`: only the tensor type (sequences and maps decode as `None`).
#[derive(Clone, PartialEq, Message)]
pub struct TypeProto {
    /// The `value` oneof.
    #[prost(oneof = "type_proto::Value", tags = "1")]
    pub value: Option<type_proto::Value>,
}

/// The `TypeProto.value` oneof.
pub mod type_proto {
    /// `TypeProto.Tensor`.
    #[derive(Clone, PartialEq, prost::Message)]
    pub struct Tensor {
        /// `elem_type` (1), `TensorProto.DataType`.
        #[prost(int32, tag = "1")]
        pub elem_type: i32,
        /// `shape` (2).
        #[prost(message, optional, tag = "2")]
        pub shape: Option<super::TensorShapeProto>,
    }

    /// `TypeProto.value`.
    #[derive(Clone, PartialEq, prost::Oneof)]
    pub enum Value {
        /// `tensor_type` (1).
        #[prost(message, tag = "1")]
        TensorType(Tensor),
    }
}

/// `TensorShapeProto`.
#[derive(Clone, PartialEq, Message)]
pub struct TensorShapeProto {
    /// `dim` (1).
    #[prost(message, repeated, tag = "1")]
    pub dim: Vec<tensor_shape_proto::Dimension>,
}

/// `TensorShapeProto.Dimension`.
pub mod tensor_shape_proto {
    /// One dimension: a size, a named symbol, or neither.
    #[derive(Clone, PartialEq, prost::Message)]
    pub struct Dimension {
        /// The `value` oneof.
        #[prost(oneof = "dimension::Value", tags = "1, 2")]
        pub value: Option<dimension::Value>,
    }

    /// The `Dimension.value` oneof.
    pub mod dimension {
        /// `dim_value` (1) or `dim_param` (2).
        #[derive(Clone, PartialEq, prost::Oneof)]
        pub enum Value {
            /// A fixed size.
            #[prost(int64, tag = "1")]
            DimValue(i64),
            /// A named (symbolic) size.
            #[prost(string, tag = "2")]
            DimParam(String),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand-encoded protobuf: field numbers and wire types as the ONNX schema gives them, so a wrong tag in
    /// the structs above fails here (not only against files written by the exporter).
    #[test]
    fn decodes_the_schema_field_numbers() {
        // ModelProto { ir_version: 8, graph: { name: "g", node: [{op_type: "Conv", input: ["x"],
        // attribute: [{name: "pads", ints: [1, 1]}]}] }, metadata_props: [{key: "k", value: "v"}] }
        let attr = [
            &[0x0a, 4][..],
            b"pads",
            &[0x40, 1, 0x40, 1], // ints (8), varint, unpacked
        ]
        .concat();
        let node = [
            &[0x0a, 1][..],
            b"x",
            &[0x22, 4],
            b"Conv",
            &[0x2a, attr.len() as u8],
            &attr,
        ]
        .concat();
        let tensor = [
            &[0x08, 2, 0x08, 3][..], // dims (1): 2, 3
            &[0x10, 1],              // data_type (2): FLOAT
            &[0x42, 1],
            b"w", // name (8)
            &[0x4a, 8],
            &1.5f32.to_le_bytes(),
            &(-2f32).to_le_bytes(), // raw_data (9)
        ]
        .concat();
        let graph = [
            &[0x0a, node.len() as u8][..],
            &node,
            &[0x12, 1],
            b"g",
            &[0x2a, tensor.len() as u8],
            &tensor,
        ]
        .concat();
        let prop = [&[0x0a, 1][..], b"k", &[0x12, 1], b"v"].concat();
        let bytes = [
            &[0x08, 8][..],
            &[0x3a, graph.len() as u8],
            &graph,
            &[0x72, prop.len() as u8],
            &prop,
            // An unknown field (99, varint) is skipped.
            &[0x98, 0x06, 7],
        ]
        .concat();
        let m = decode_model(&bytes).unwrap();
        assert_eq!(m.ir_version, 8);
        assert_eq!(m.metadata_props[0].key, "k");
        assert_eq!(m.metadata_props[0].value, "v");
        let g = m.graph.unwrap();
        assert_eq!(g.name, "g");
        assert_eq!(g.node[0].op_type, "Conv");
        assert_eq!(g.node[0].input, vec!["x".to_string()]);
        assert_eq!(g.node[0].attribute[0].name, "pads");
        assert_eq!(g.node[0].attribute[0].ints, vec![1, 1]);
        let t = &g.initializer[0];
        assert_eq!(
            (t.dims.clone(), t.data_type, t.name.as_str()),
            (vec![2, 3], FLOAT, "w")
        );
        assert_eq!(&t.raw_data[..4], &1.5f32.to_le_bytes());
        // Truncated: an error, not a panic.
        assert!(decode_model(&bytes[..bytes.len() - 6]).is_err());
    }
}

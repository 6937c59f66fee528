//! Reading and writing an output port by its bytes, whatever type it
//! carries (`nerve echo`, `hz`, the recorder, `nerve replay`, `nerve pub`),
//! under the path the tools have always used: see [`crate::port::bytes`].

pub use crate::port::bytes::{Loan, RawOutput, RawPort};
pub use crate::port::service::port_identity;

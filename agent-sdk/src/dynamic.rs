//! Ports declared by a payload's [`shm_schemas::Schema`] instead of its
//! Rust type, for agents that learn their types at run time (the Python
//! agents), under the path they have always used: they are the byte port
//! of [`crate::port::bytes`], which every typed port is a view of, so a
//! Rust agent and a Python agent read each other's samples. Calls too
//! ([`crate::port::schema_call`]): a service and a client of two layouts,
//! on the service a typed call of those layouts makes.

pub use crate::port::bytes::{Loan, Received, SchemaInput, SchemaOutput};
pub use crate::port::schema_call::{Layout, SchemaClient, SchemaServer, SeqAnswerLoan, ServeError};

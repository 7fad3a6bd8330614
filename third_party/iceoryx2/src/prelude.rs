// Copyright (c) 2023 Contributors to the Eclipse Foundation
//
// See the NOTICE file(s) distributed with this work for additional
// information regarding copyright ownership.
//
// This program and the accompanying materials are made available under the
// terms of the Apache Software License 2.0 which is available at
// https://www.apache.org/licenses/LICENSE-2.0, or the MIT license
// which is available at https://opensource.org/licenses/MIT.
//
// SPDX-License-Identifier: Apache-2.0 OR MIT

pub use crate::config::Config;
pub use crate::node::{Node, NodeBuilder, NodeState, node_name::NodeName};
pub use crate::port::{
    EventActivation, backpressure_strategy::BackpressureStrategy, event_id::EventId,
    port_name::PortName,
};
pub use crate::service::header::payload_header::PayloadHeader;
pub use crate::service::marker::Flatbuffer;
pub use crate::service::messaging_pattern::MessagingPattern;
pub use crate::service::{
    Service, ServiceDetails, attribute::AttributeSet, attribute::AttributeSpecifier,
    attribute::AttributeVerifier, ipc, ipc_threadsafe, local, local_threadsafe,
    port_factory::PortFactory, service_name::ServiceName,
};
pub use crate::signal_handling_mode::SignalHandlingMode;
pub use crate::waitset::{WaitSet, WaitSetAttachmentId, WaitSetBuilder, WaitSetGuard};
pub use iceoryx2_bb_container::semantic_string::SemanticString;
pub use iceoryx2_bb_container::semantic_string::SemanticStringError;
pub use iceoryx2_bb_derive_macros::PlacementDefault;
pub use iceoryx2_bb_derive_macros::ZeroCopySend;
pub use iceoryx2_bb_elementary::CallbackProgression;
pub use iceoryx2_bb_elementary::alignment::Alignment;
pub use iceoryx2_bb_elementary::allocation_strategy::AllocationStrategy;
pub use iceoryx2_bb_elementary_traits::iceoryx_send::IceoryxSend;
pub use iceoryx2_bb_elementary_traits::placement_default::PlacementDefault;
pub use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
pub use iceoryx2_bb_flatbuffers::FlatbufferError;
pub use iceoryx2_bb_posix::file_descriptor::{FileDescriptor, FileDescriptorBased};
pub use iceoryx2_bb_posix::file_descriptor_set::SynchronousMultiplexing;
pub use iceoryx2_bb_posix::process::ProcessId;
pub use iceoryx2_bb_print::{cerr, cerrln, cout, coutln};
pub use iceoryx2_bb_system_types::{file_name::FileName, file_path::FilePath, path::Path};
pub use iceoryx2_log::LogLevel;
pub use iceoryx2_log::set_log_level;
#[cfg(feature = "std")]
pub use iceoryx2_log::set_log_level_from_env_or;
#[cfg(feature = "std")]
pub use iceoryx2_log::set_log_level_from_env_or_default;
pub use iceoryx2_log::set_logger;

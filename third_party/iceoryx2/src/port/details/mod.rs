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

pub mod chunk;
pub mod chunk_details;
pub mod chunk_mut_shared_state;
pub mod data_segment;
pub mod data_segment_shared_state;
pub mod receiver;
pub mod segment_state;
pub mod sender;

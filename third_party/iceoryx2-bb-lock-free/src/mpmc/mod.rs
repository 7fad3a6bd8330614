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

//! Multi producer multi consumer constructs

pub mod bit_set;
pub mod container;
pub mod counting_bit_set;
pub mod robust_unique_index_set;
pub mod unique_index_set;
pub mod unique_index_set_enums;

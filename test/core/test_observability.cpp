// SPDX-License-Identifier: BSD-3-Clause
// Placeholder
#include <gtest/gtest.h>
#include "skin3d/slam/observability.h"
TEST(Placeholder, Builds) { SUCCEED(); }

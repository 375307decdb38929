// SPDX-License-Identifier: BSD-3-Clause
// Placeholder: being written (issue 5).
#include "skin3d/slam/observability.h"
int main() { return 0; }

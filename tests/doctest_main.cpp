// SPDX-License-Identifier: BSD-3-Clause
// Single doctest main shared by every suite.
#define DOCTEST_CONFIG_IMPLEMENT_WITH_MAIN
#include <doctest/doctest.h>

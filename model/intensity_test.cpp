#include <gtest/gtest.h>

#include "model/intensity.h"

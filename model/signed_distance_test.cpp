#include <gtest/gtest.h>

#include "model/signed_distance.h"

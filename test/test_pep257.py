# Copyright 2015 Open Source Robotics Foundation, Inc.
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

from pathlib import Path

from ament_pep257.main import main
import pytest

# The upstream template lints '.' and 'test'; name the package's own files instead, so that
# the result does not depend on where pytest starts and .venv/ is never linted.
PACKAGE_ROOT = Path(__file__).resolve().parent.parent
LINTED_PATHS = [str(PACKAGE_ROOT / name)
                for name in ('mech_balance', 'test', 'launch', 'examples', 'setup.py')]


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    rc = main(argv=LINTED_PATHS)
    assert rc == 0, 'Found code style errors / warnings'

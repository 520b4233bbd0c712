"""A law plug-in that raises while importing (``MWIP_ROS_LAWS=broken_plugin``): the tools and nodes must stop with
one line naming it, exit 2 (test/cli/test_law_errors.py)."""
raise RuntimeError("broken_plugin's own import error")

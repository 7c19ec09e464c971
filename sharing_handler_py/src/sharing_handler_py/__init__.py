"""Fleet obstacle sharing: the SharingHandler (pure logic in ``logic``, rospy node in ``node``)."""
